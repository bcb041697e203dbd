"""The report, the history and the baseline commands on a small real history.

The report is opened in a real headless Chromium (Debian's chromium, installed
by .ci/run): a copy of the page gets a few lines of script that record, once
the page has loaded, which images decoded and which sections have a height;
``--dump-dom`` prints the page with those marks.
"""

import base64
import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from headless_chromium import CHROMIUM, body_marks, command
from monitor_rig import ALPHA, judge, make_base, night

from imu_square.cli import main
from imu_square.monitor.report.html import SECTIONS

PROBE = """<script>
window.addEventListener("load", () => {
  const imgs = [...document.images];
  const ok = imgs.filter((i) => i.complete && i.naturalWidth > 100 && i.naturalHeight > 100);
  const shown = [...document.querySelectorAll("section")].filter((s) => s.offsetHeight > 20);
  document.body.dataset.images = String(imgs.length);
  document.body.dataset.imagesOk = String(ok.length);
  document.body.dataset.sections = shown.map((s) => s.id).join(",");
});
</script></body>"""


@pytest.fixture(scope="module")
def machine(tmp_path_factory):
    """A history with a 3-night baseline, an anchor, 3 judged nights and an invalid one."""
    folder = make_base(tmp_path_factory.mktemp("report"), nights=3)
    config = folder / "monitor.toml"
    assert main(["baseline", "anchor", "--config", str(config), "--ballbar", "21.5"]) == 0
    for day in (3, 4, 5):
        code, record = judge(config, night(folder, day), None)
        assert record["state"] in ("ok", "warning") and code in (0, 10)
        # the anchored baseline adds the absolute machine squareness
        assert record["machine_squareness_urad"] == pytest.approx(
            21.5 + record["change_urad"], abs=1e-9
        )
    junk = folder / "junk.mcap"
    junk.write_bytes(b"not a recording")
    code, record = judge(config, junk, None)
    assert record["state"] == "invalid" and code == 12
    return folder


@pytest.mark.slow
def test_report_is_self_contained_and_renders_in_a_real_browser(machine, tmp_path):
    out = tmp_path / "report.html"
    assert main(["report", "--config", str(machine / "monitor.toml"), "-o", str(out)]) == 0
    html = out.read_text(encoding="utf-8")
    for section in SECTIONS:
        assert f'<section id="{section}">' in html
    images = re.findall(r'src="data:image/png;base64,([^"]+)"', html)
    assert len(images) == 3  # trend, last run (Fig. 5), sensor (the rig fits no diagnostics)
    for data in images:
        png = base64.b64decode(data)
        assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 20_000
    assert not re.search(r'(src|href)="(?!data:)', html), "the page must not load anything"
    assert "anchor by ballbar" in html and "+21.5 µm/m" in html
    if CHROMIUM is None:
        pytest.skip("no chromium to open the report (Debian package chromium; .ci/run installs it)")
    probed = tmp_path / "probed.html"
    probed.write_text(html.replace("</body>", PROBE), encoding="utf-8")
    marks, _ = body_marks(probed, tmp_path / "profile")
    assert marks["images"] == "3" and marks["images-ok"] == "3", marks
    assert set(marks["sections"].split(",")) == set(SECTIONS), marks


WIDTH_PROBE = """<script>
window.addEventListener("load", () => {
  const root = document.documentElement;
  document.body.dataset.scrollWidth = String(root.scrollWidth);
  document.body.dataset.clientWidth = String(root.clientWidth);
});
</script></body>"""


@pytest.mark.slow
@pytest.mark.parametrize("width", [1280, 390])
def test_the_report_has_no_horizontal_overflow_on_a_screen_or_a_phone(machine, tmp_path, width):
    # A recording under a deep archive path, whose name no line can break at a space.
    deep = tmp_path.joinpath(*["a-shop-archive-folder-with-a-long-name"] * 4)
    deep.mkdir(parents=True)
    long_night = deep / ("nightly-warm-up-of-machine-m1-" + "x" * 60 + ".mcap")
    shutil.copy(night(tmp_path, 7), long_night)
    folder = tmp_path / "copy"
    shutil.copytree(machine, folder)
    _, record = judge(folder / "monitor.toml", long_night, None)
    assert record["state"] in ("ok", "warning")  # the latest valid run, drawn in the report
    out = tmp_path / "report.html"
    assert main(["report", "--config", str(folder / "monitor.toml"), "-o", str(out)]) == 0
    if CHROMIUM is None:
        pytest.skip("no chromium to open the report (Debian package chromium; .ci/run installs it)")
    probed = tmp_path / "probed.html"
    probed.write_text(out.read_text(encoding="utf-8").replace("</body>", WIDTH_PROBE))
    window = f"--window-size={width},2000"
    marks, _ = body_marks(probed, tmp_path / "profile", window)
    assert int(marks["client-width"]) > 0.9 * width - 20, marks  # the window asked for
    assert int(marks["scroll-width"]) <= int(marks["client-width"]), marks
    # A picture to look at when this fails.
    subprocess.run(
        [
            *command(tmp_path / "profile", window),
            f"--screenshot={tmp_path / 'report.png'}",
            out.as_uri(),
        ],
        capture_output=True,
        timeout=120,
    )
    assert (tmp_path / "report.png").stat().st_size > 10_000


def test_a_long_figure_title_stays_inside_the_figure(tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib import pyplot as plt

    from imu_square.io.mcap import read_mcap
    from imu_square.pipeline.run_figure import plot_results
    from imu_square.pipeline.squareness import AnalysisOptions, analyze

    result = analyze(read_mcap(night(tmp_path, 8)), AnalysisOptions(bootstrap_n=0))
    seen = {}
    real_savefig = plt.Figure.savefig

    def savefig(fig, *args, **kwargs):
        real_savefig(fig, *args, **kwargs)
        box = fig._suptitle.get_window_extent(fig.canvas.get_renderer())
        seen["inside"] = box.x0 >= 0 and box.x1 <= fig.bbox.width
        seen["lines"] = fig._suptitle.get_text().count("\n") + 1

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(plt.Figure, "savefig", savefig)
        plot_results([result], tmp_path / "f.png", title="nightly warm-up of mill 3 " * 6)
    assert seen["inside"]


@pytest.mark.slow
def test_history_table_json_plot_since_and_backup(machine, tmp_path, capsys):
    config = str(machine / "monitor.toml")
    assert main(["history", "--config", config, "--json", "--plot", str(tmp_path / "t.png")]) == 0
    captured = capsys.readouterr()
    records = [json.loads(line) for line in captured.out.splitlines()]
    assert [r["state"] for r in records][:3] == ["ok", "ok", "ok"]  # the baseline's nights
    assert records[-1]["state"] == "invalid" and records[-1]["invalid_reason"]
    assert (tmp_path / "t.png").read_bytes()[:4] == b"\x89PNG"
    assert "invalid" in captured.err and "baseline" in captured.err
    assert main(["history", "--config", config, "--json", "--since", "2026-09-05"]) == 0
    later = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    # nights 4 and 5 (09-05, 09-06) and the junk file, timed by its modification
    assert [r["state"] for r in later] == ["ok", "ok", "invalid"]
    assert all(r["recorded_at"] >= "2026-09-05" for r in later)
    missing = tmp_path / "not-mounted" / "copy.db"
    assert main(["history", "--config", config, "--backup", str(missing)]) == 2
    assert "does not exist" in capsys.readouterr().err and not missing.parent.exists()
    assert main(["history", "--config", config, "--backup", str(tmp_path / "copy.db")]) == 0
    capsys.readouterr()
    assert main(["history", "--config", config, "--since", "5 Sept"]) == 2
    assert "--since must be a date YYYY-MM-DD, got '5 Sept'" in capsys.readouterr().err


@pytest.mark.slow
def test_baseline_show_and_anchor_by_diagonals(machine, tmp_path, capsys):
    config = str(machine / "monitor.toml")
    assert main(["baseline", "show", "--config", config, "--json"]) == 0
    shown = json.loads(capsys.readouterr().out)
    assert len(shown["run_ids"]) == 3 and shown["alarm_design"]["arl0_nights"] == 730
    assert shown["anchors"][0]["machine_squareness_urad"] == pytest.approx(21.5)
    # ISO 230-6 face diagonals of 600 x 400 mm on a machine of +20 µm/m:
    # S = D0 (D1 - D2) / (2 X Y), so D1 - D2 = 2 X Y S / D0
    d0 = (600**2 + 400**2) ** 0.5
    diff = 2 * 600 * 400 * ALPHA / d0
    code = main(
        [
            "baseline", "anchor", "--config", config,
            "--diagonals", f"{d0 + diff / 2:.6f}", f"{d0 - diff / 2:.6f}",
            "--travel-mm", "600", "400",
        ]
    )  # fmt: skip
    assert code == 0
    capsys.readouterr()
    assert main(["baseline", "show", "--config", config, "--json"]) == 0
    anchors = json.loads(capsys.readouterr().out)["anchors"]
    assert anchors[-1]["method"] == "diagonals"
    assert anchors[-1]["machine_squareness_urad"] == pytest.approx(20.0, abs=0.01)
    bad = ["baseline", "anchor", "--config", config, "--diagonals", "700", "700"]
    assert main([*bad, "--travel-mm", "600", "400"]) == 2
    assert "more than 0.1 % off (check the units: mm)" in capsys.readouterr().err
    assert main(bad) == 2
    assert "--diagonals needs --travel-mm" in capsys.readouterr().err


@pytest.mark.slow
def test_results_go_to_stdout_and_the_format_does_not_follow_the_terminal(machine, tmp_path):
    # `imu-square history > h.txt` used to give an empty file: the table went to stderr.
    # And replay wrote JSON lines to stdout whenever stderr was not a terminal (cron).
    script = Path(sys.executable).with_name("imu-square")
    config = str(machine / "monitor.toml")

    def run(*argv):
        return subprocess.run(
            [str(script), *argv], capture_output=True, text=True, timeout=300, check=False
        )

    table = run("history", "--config", config)
    assert table.returncode == 0 and table.stdout.splitlines()[0].split()[:2] == ["run", "recorded"]
    assert "invalid" in table.stdout
    shown = run("baseline", "show", "--config", config)
    assert shown.returncode == 0 and shown.stdout.startswith("baseline ")
    replayed = run("replay", "--config", config, "--jobs", "1", str(machine / "night-003.mcap"))
    assert replayed.returncode == 0 and replayed.stdout.startswith("replayed 1 recording(s)")
    assert "{" not in replayed.stdout  # no JSON without --json, terminal or not
