"""The bytes of the MCAP records the reader parses itself, named after the specification.

The reader walks a file record by record and picks messages out of a chunk
through its message indexes without building record objects, so it needs the
byte layout of the records involved [1]_. Every record is an ``opcode``
(uint8) and a ``record length`` (uint64) followed by that many bytes of
content; integers are little-endian.

References
----------
.. [1] MCAP format specification, https://mcap.dev/spec
"""

import struct

import numpy as np

# Every record: opcode uint8, record length uint64 (of the content that follows).
RECORD_PREFIX = struct.Struct("<BQ")
# channel_id uint16: the first field of a Message and of a Message Index.
CHANNEL_ID = struct.Struct("<H")
# Message content: channel_id uint16, sequence uint32, log_time uint64, publish_time uint64,
# then its data up to the end of the record.
MESSAGE_FIELDS = struct.Struct("<HIQQ")
# Message Index content: channel_id uint16, then its records: their byte length (uint32)
# and that many bytes of (log_time uint64, offset uint64) pairs, the offset of a message in
# the uncompressed records of the chunk before.
MESSAGE_INDEX_FIELDS = struct.Struct("<HI")
MESSAGE_INDEX_ENTRY = np.dtype([("log_time", "<u8"), ("offset", "<u8")])
# A Message record's start: opcode, record length, channel_id; as a struct for one record,
# as a numpy record for many at once.
MESSAGE_START = struct.Struct("<BQH")
MESSAGE_START_DTYPE = np.dtype([("opcode", "u1"), ("record_length", "<u8"), ("channel_id", "<u2")])
