"""The documentation: the README's promises, and the site built by ``python3 dev.py docs``.

The tests of the built site read ``docs/_build/html``. ``.ci/run`` builds it
(warnings as errors, the gallery run) before the tests and sets
``IMU_SQUARE_DOCS_BUILT=1``, so that a missing site fails there; elsewhere a
missing site skips them, saying how to build it. The pages are opened in a
real headless Chromium (Debian's chromium, as the report's tests use).
"""

import functools
import os
import re
import shlex
import sys
from html.parser import HTMLParser
from pathlib import Path
from urllib.parse import unquote, urlsplit

import pytest
from headless_chromium import CHROMIUM, body_marks

from imu_square.cli import build_parser, commands

ROOT = Path(__file__).resolve().parents[1]
SITE = ROOT / "docs" / "_build" / "html"
README = ROOT / "README.md"


@pytest.fixture(scope="module")
def site():
    if not (SITE / "index.html").exists():
        if os.environ.get("IMU_SQUARE_DOCS_BUILT"):
            pytest.fail(f"IMU_SQUARE_DOCS_BUILT is set but {SITE} has no index.html")
        pytest.skip("the documentation site is not built: python3 dev.py docs")
    return SITE


# --- the ground truth: what the code accepts ---------------------------------------------


def _command_parsers():
    """``{("baseline", "set"): parser, ...}``: every command and sub-command in full."""
    import argparse

    out = {}

    def walk(parser, path):
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                for name, sub in action.choices.items():
                    out[(*path, name)] = sub
                    walk(sub, (*path, name))

    walk(build_parser(full=True), ())
    return out


def _accepted_fields(table, doc):
    """The fields the monitor's reader accepts in ``table``, as its refusal lists them."""
    from imu_square.errors import ImuSquareError
    from imu_square.monitor.config import monitor_from_mapping

    with pytest.raises(ImuSquareError, match="unknown field") as caught:
        monitor_from_mapping(doc, ROOT / "monitor.toml")
    allowed = re.search(r"\[(.+?)\] has unknown field .*?allowed: \[(.*?)\]", str(caught.value))
    assert allowed and allowed.group(1) == table, str(caught.value)
    return set(re.findall(r"'([^']+)'", allowed.group(2)))


@functools.cache
def monitor_fields():
    """``{"[alerts.email]": {fields}}``: every table of the monitor file and its fields."""
    from imu_square.monitor.alerts.config import SINK_KINDS
    from imu_square.monitor.config import SECTIONS

    out = {}
    for section in SECTIONS:
        doc = {"monitor": {"machine_id": "m"}}
        doc.setdefault(section, {})["zz_not_a_field"] = 1
        out[f"[{section}]"] = _accepted_fields(section, doc)
    for kind in SINK_KINDS:
        doc = {"monitor": {"machine_id": "m"}, "alerts": {kind: {"zz_not_a_field": 1}}}
        out[f"[alerts.{kind}]"] = _accepted_fields(f"alerts.{kind}", doc)
    return out


# --- the README ----------------------------------------------------------------------------


def _example_commands(path):
    """Every ``imu-square ...`` command in a page's code blocks, continuations joined."""
    out, pending, fence = [], "", False
    for line in path.read_text(encoding="utf-8").splitlines():
        if line.startswith("```"):
            fence, pending = not fence and not line.startswith("```{"), ""
            continue
        if not (fence or line.startswith("    ")):
            pending = ""
            continue
        code = re.sub(r"\s+#.*$", "", line.strip())
        if code.endswith("\\"):
            pending += code[:-1] + " "
            continue
        command, pending = (pending + code).strip(), ""
        if command.startswith("imu-square "):
            out.append(command)
    return out


def test_the_readme_is_short_and_keeps_its_two_commands():
    text = README.read_text(encoding="utf-8")
    assert 150 <= len(text.splitlines()) <= 200
    for command in ("python3 dev.py nightly", "python3 dev.py test"):
        assert f"    {command} " in text, command
    # CI runs the README's test command
    assert "python3 dev.py test" in (ROOT / ".ci" / "run").read_text(encoding="utf-8")
    # the picture it shows ships with it
    for target in re.findall(r"\]\(([^)#]+)\)", text):
        if "://" not in target:
            assert (ROOT / target).exists(), target


def test_the_readme_lists_every_command_and_each_example_parses():
    text = README.read_text(encoding="utf-8")
    listed = set(re.findall(r"^\| `([a-z-]+)` \|", text, flags=re.MULTILINE))
    assert listed == set(commands()), listed ^ set(commands())
    examples = _example_commands(README)
    assert len(examples) >= 5, examples
    parser = build_parser(full=True)
    for example in examples:
        try:
            parser.parse_args(shlex.split(example)[1:])
        except SystemExit:
            pytest.fail(f"the README's command does not parse: {example}")


def _is_synopsis(command):
    """A usage line (``[--json]``, ``a|b``, ``...``, ``RUN.mcap``-style placeholders)."""
    return bool(re.search(r"[\[\]|]|\.\.\.|\b[A-Z][A-Z0-9_]*[A-Z0-9]\b", command))


def test_the_user_guides_example_commands_parse():
    parser = build_parser(full=True)
    examples = [
        (page.name, command)
        for page in sorted((ROOT / "docs" / "user-guide").glob("*.md"))
        for command in _example_commands(page)
        if not _is_synopsis(command)
    ]
    assert len(examples) >= 15, examples
    for page, example in examples:
        try:
            parser.parse_args(shlex.split(example)[1:])
        except SystemExit:
            pytest.fail(f"{page}: the example command does not parse: {example}")


def test_the_readme_verdict_has_the_form_the_monitor_prints():
    from imu_square.monitor import demo

    line = re.search(r"^    (demo-mill: squareness .*)$", README.read_text("utf-8"), re.M)
    assert line, "the README shows the demo's verdict line"
    form = (
        rf"{demo.MACHINE_ID}: squareness unchanged \([+-]\d+\.\d ± \d+\.\d µm/m \(k=1\) "
        r"since the baseline of \d{4}-\d\d-\d\d\); diagnostic alarm: backlash_x "
        r"[+-]\d+\.\d+ ± \d+\.\d+ µm since the baseline: check the machine"
    )
    assert re.fullmatch(form, line.group(1)), line.group(1)


# --- the generated reference ---------------------------------------------------------------


def test_the_files_reference_generator_knows_every_monitor_field():
    pytest.importorskip("docutils", reason="the docs extra is not installed: pip install .[docs]")
    sys.path.insert(0, str(ROOT / "docs" / "_ext"))
    try:
        import imu_docs
    finally:
        sys.path.remove(str(ROOT / "docs" / "_ext"))
    tables = imu_docs.file_tables("monitor")
    for label, fields in monitor_fields().items():
        assert label in tables, label
        assert {row[0] for row in tables[label]} >= fields, (label, fields)


def test_every_command_and_option_is_in_the_cli_reference(site):
    html = (site / "reference" / "cli.html").read_text(encoding="utf-8")
    parsers = _command_parsers()
    assert {path[0] for path in parsers} == set(commands())
    ids = {"imu-square-" + "-".join(path): path for path in parsers}
    starts = [(m.start(), m.group(1)) for m in re.finditer(r'<section id="([^"]+)"', html)]
    command_starts = [(at, ids[name]) for at, name in starts if name in ids]
    assert {path for _, path in command_starts} == set(parsers), set(parsers) - {
        path for _, path in command_starts
    }
    ends = [at for at, _ in command_starts[1:]] + [len(html)]
    for (at, path), end in zip(command_starts, ends, strict=True):
        shown = set()
        for kbd in re.findall(r"<kbd>(.*?)</kbd>", html[at:end]):
            shown.update(part.strip() for part in kbd.split(","))
        for action in parsers[path]._actions:
            if action.help == "==SUPPRESS==" or action.dest == "help":
                continue
            names = action.option_strings or [action.metavar or action.dest]
            if isinstance(names[0], tuple) or action.__class__.__name__ == "_SubParsersAction":
                continue
            assert set(names) <= shown, (path, names)


def test_every_monitor_field_is_in_the_files_reference(site):
    html = (site / "reference" / "files.html").read_text(encoding="utf-8")
    monitor = html[html.index('<section id="monitor-file"') :]
    monitor = monitor[: monitor.index('<section id="csv-format"')]
    for label, fields in monitor_fields().items():
        at = monitor.index(f'<p class="rubric">{label}</p>')
        table = monitor[at : monitor.index("</table>", at)]
        shown = set(re.findall(r'<span class="pre">([^<]+)</span>', table))
        assert fields <= shown, (label, fields - shown)


# --- links and pages -----------------------------------------------------------------------


class _Links(HTMLParser):
    def __init__(self):
        super().__init__()
        self.links, self.ids = [], set()

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        for key in ("id", "name"):
            if attrs.get(key):
                self.ids.add(attrs[key])
        for key in ("href", "src"):
            if attrs.get(key) and tag in ("a", "link", "img", "script", "iframe"):
                self.links.append(attrs[key])


@functools.cache
def _parsed(path):
    parser = _Links()
    parser.feed(path.read_text(encoding="utf-8"))
    return parser


def test_no_internal_link_of_the_site_is_broken(site):
    broken = []
    # the site's pages (the theme's templates under _static are not pages)
    pages = sorted(p for p in site.rglob("*.html") if "_static" not in p.relative_to(site).parts)
    assert len(pages) > 30
    for page in pages:
        for link in _parsed(page).links:
            parts = urlsplit(link)
            if parts.scheme or parts.netloc:
                continue  # outside the site (and data: images)
            target = (page.parent / unquote(parts.path)).resolve() if parts.path else page
            if target.is_dir():
                target = target / "index.html"
            if not target.exists():
                broken.append(f"{page.relative_to(site)}: {link}")
            elif parts.fragment and target.suffix == ".html":
                if unquote(parts.fragment) not in _parsed(target).ids:
                    broken.append(f"{page.relative_to(site)}: {link} (no such anchor)")
    assert not broken, "\n".join(broken[:40])


PROBE = """<script>
window.addEventListener("load", () => {
  const imgs = [...document.images];
  const ok = imgs.filter((i) => i.complete && i.naturalWidth > 0);
  const main = document.querySelector("main") || document.body;
  document.body.dataset.images = String(imgs.length);
  document.body.dataset.imagesOk = String(ok.length);
  document.body.dataset.styles = String(document.styleSheets.length);
  document.body.dataset.mainHeight = String(main.offsetHeight);
  document.body.dataset.title = document.title;
});
</script></body>"""


def _open_in_chromium(page, tmp_path):
    """The page's body attributes after loading it, with the probe, in headless Chromium."""
    probed = page.with_name(f"probed-{page.name}")
    probed.write_text(page.read_text(encoding="utf-8").replace("</body>", PROBE), "utf-8")
    try:
        return body_marks(probed, tmp_path / "profile")
    finally:
        probed.unlink()


@pytest.mark.slow
@pytest.mark.parametrize(
    ("page", "words"),
    [
        ("index.html", ["User guide", "Gallery", "Theory", "Reference"]),
        ("auto_examples/plot_crash_alarm.html", ["check the machine", "baseline set from"]),
        ("reference/cli.html", ["--ballbar", "--separate-gravity", "--machine-id"]),
    ],
)
def test_the_built_pages_load_in_a_real_browser(site, tmp_path, page, words):
    if CHROMIUM is None:
        pytest.skip("no chromium to open the pages (Debian package chromium; .ci/run installs it)")
    marks, dom = _open_in_chromium(site / page, tmp_path)
    assert int(marks["styles"]) >= 2, marks  # the theme's style sheets loaded
    assert int(marks["main-height"]) > 300, marks
    assert marks["images"] == marks["images-ok"], marks
    if page.startswith("auto_examples"):
        assert int(marks["images"]) >= 1, marks  # the example's figure
    for word in words:
        assert word in dom, word


def test_the_machine_file_of_the_compare_example_is_chapman_machine_7():
    # The user guide's compare example runs on it; it must stay the machine the
    # reference tests check (tests/test_compare.py builds it in code).
    from imu_square.simulate import data_path, read_machine
    from imu_square.simulate.geometry import chapman_machine

    shipped = read_machine(data_path("machine_chapman7_yaw.toml")).geometry
    expected = chapman_machine(7, yaw=True)
    for field, value in vars(expected).items():
        assert getattr(shipped, field) == pytest.approx(value, rel=1e-12, abs=1e-15), field
