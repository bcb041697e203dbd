// Independent reader for imu-square MCAP files, with the TypeScript @mcap/core package.
//
// Usage: node check_mcap.mjs FILE.mcap
//
// Reads FILE twice: once through the summary and chunk indexes (McapIndexedReader) and once
// record by record from the magic to the footer (McapStreamReader, chunk CRCs validated).
// Prints one JSON object on stdout: header profile, schemas, channels, per-topic message counts
// and first/last log times from both passes, the statistics record, metadata names and
// attachments; the number of samples in the imu_square/msg/AccelBatch messages (the uint32
// sample count at byte 20 of each CDR message) and the kinds of the JSON event messages.
// Exits non-zero when the two passes disagree or the file does not parse.
import { open, readFile } from "node:fs/promises";
import { McapIndexedReader, McapStreamReader } from "@mcap/core";
import { FileHandleReadable } from "@mcap/nodejs";
import { loadDecompressHandlers } from "@mcap/support";

function countMessage(table, topic, logTime, bytes) {
  const entry = table[topic] ?? { count: 0, bytes: 0, first_log_time: null, last_log_time: null };
  entry.count += 1;
  entry.bytes += bytes;
  if (entry.first_log_time === null || logTime < BigInt(entry.first_log_time)) {
    entry.first_log_time = logTime.toString();
  }
  if (entry.last_log_time === null || logTime > BigInt(entry.last_log_time)) {
    entry.last_log_time = logTime.toString();
  }
  table[topic] = entry;
}

async function readIndexed(path, decompressHandlers) {
  const handle = await open(path, "r");
  try {
    const reader = await McapIndexedReader.Initialize({
      readable: new FileHandleReadable(handle),
      decompressHandlers,
    });
    const messages = {};
    const eventKinds = {};
    let samples = 0;
    for await (const message of reader.readMessages({ validateCrcs: true })) {
      const channel = reader.channelsById.get(message.channelId);
      countMessage(messages, channel.topic, message.logTime, message.data.byteLength);
      const schema = reader.schemasById.get(channel.schemaId);
      if (schema?.name === "imu_square/msg/AccelBatch") {
        const view = new DataView(message.data.buffer, message.data.byteOffset);
        samples += view.getUint32(20, true);
      } else if (channel.messageEncoding === "json") {
        const kind = JSON.parse(new TextDecoder().decode(message.data)).kind;
        eventKinds[kind] = (eventKinds[kind] ?? 0) + 1;
      }
    }
    const metadata = [];
    for await (const record of reader.readMetadata()) {
      metadata.push({ name: record.name, keys: [...record.metadata.keys()].sort() });
    }
    const stats = reader.statistics;
    return {
      profile: reader.header.profile,
      library: reader.header.library,
      schemas: [...reader.schemasById.values()].map((s) => ({
        id: s.id,
        name: s.name,
        encoding: s.encoding,
      })),
      channels: [...reader.channelsById.values()].map((c) => ({
        id: c.id,
        topic: c.topic,
        schema_id: c.schemaId,
        message_encoding: c.messageEncoding,
      })),
      statistics: stats && {
        message_count: stats.messageCount.toString(),
        schema_count: stats.schemaCount,
        channel_count: stats.channelCount,
        chunk_count: stats.chunkCount,
        channel_message_counts: Object.fromEntries(
          [...stats.channelMessageCounts].map(([id, n]) => [id, n.toString()]),
        ),
      },
      chunk_compression: [...new Set(reader.chunkIndexes.map((c) => c.compression))],
      metadata,
      attachments: reader.attachmentIndexes.map((a) => a.name),
      messages,
      samples,
      event_kinds: eventKinds,
    };
  } finally {
    await handle.close();
  }
}

function readStream(bytes, decompressHandlers) {
  const reader = new McapStreamReader({ decompressHandlers, validateCrcs: true });
  reader.append(bytes);
  const channels = new Map();
  const messages = {};
  let records = 0;
  for (let record; (record = reader.nextRecord()); ) {
    records += 1;
    if (record.type === "Channel") {
      channels.set(record.id, record.topic);
    } else if (record.type === "Message") {
      countMessage(messages, channels.get(record.channelId), record.logTime, record.data.byteLength);
    }
  }
  return { complete: reader.done(), records, messages };
}

const path = process.argv[2];
if (!path) {
  console.error("usage: node check_mcap.mjs FILE.mcap");
  process.exit(2);
}
const decompressHandlers = await loadDecompressHandlers();
const indexed = await readIndexed(path, decompressHandlers);
const stream = readStream(await readFile(path), decompressHandlers);
const canonical = (table) =>
  JSON.stringify(Object.keys(table).sort().map((topic) => [topic, table[topic]]));
const agree = canonical(indexed.messages) === canonical(stream.messages);
console.log(JSON.stringify({ ...indexed, stream, passes_agree: agree }, null, 1));
if (!agree || !stream.complete) {
  console.error(`${path}: indexed and streamed reads disagree or the stream is incomplete`);
  process.exit(1);
}
