"""The README's first command: ``imu-square nightly --demo DIR``, end to end.

Six weeks of simulated nights are judged into a fresh SQLite history, then
tonight streams through the emulated board on a pseudo-terminal. The demo's
story is its truth: a crash of +45 µm/m on night 23, repaired on night 28 to
31.5 µm/m (from 30) and a new baseline; cold nights and a cut recording are
not judged.
"""

import json
import re
from pathlib import Path

import pytest
from doc_quotes import form_of

from imu_square.cli import main
from imu_square.monitor import demo

README = Path(__file__).resolve().parents[1] / "README.md"


@pytest.mark.slow
def test_the_demo_night_ends_in_a_verdict_a_chart_and_a_report(tmp_path, capsys):
    folder = tmp_path / "demo"
    code = main(["nightly", "--demo", str(folder), "--json"])
    out = capsys.readouterr()
    tonight = json.loads(out.out.strip().splitlines()[-1])
    # ok, or warning on the 2 % of in-control nights the charts are designed to warn on
    # (tonight's emulated board is not seeded)
    assert (tonight["state"], code) in (("ok", 0), ("warning", 10)), tonight
    assert tonight["machine_id"] == demo.MACHINE_ID
    # tonight's machine is the repaired one, against the baseline set after the repair
    assert abs(tonight["change_urad"]) < 4 * tonight["u_change_urad"]
    data = folder / "data"
    for name in (f"{demo.MACHINE_ID}-trend.png", f"{demo.MACHINE_ID}-report.html"):
        assert (data / name).stat().st_size > 10_000, name
    assert json.loads((data / "latest-alert.json").read_text())["state"] == tonight["state"]

    assert main(["history", "--config", str(folder / "monitor.toml"), "--json"]) == 0
    records = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    states = [r["state"] for r in records]
    assert len(states) == demo.NIGHTS + 1
    # the +45 µm/m crash (2.6 sigma a night) fires within the nights before the repair and
    # stands until the new baseline; no alarm before it or under the new baseline
    first = states.index("alarm")
    renewed = demo.NEW_BASELINE_NIGHTS[0]
    assert demo.CRASH_NIGHT <= first < demo.REPAIR_NIGHT
    assert set(states[first:renewed]) == {"alarm"} and "alarm" not in states[renewed:]
    assert records[first]["change_urad"] > 2 * records[first]["u_change_urad"]
    assert states[demo.CUT_NIGHT] == "invalid"
    # a night the verdict does not judge charts no diagnostic and raises no diagnostic alarm
    for r in records:
        if r["state"] == "invalid":
            assert not r["diagnostics"] and "diagnostic alarm" not in r["verdict"], r["verdict"]
    # the demo's own settings cause no warning (its analysis follows its program)
    assert not [w for r in records for w in r["warnings"] if "cutoff" in w]
    assert all(states[n] == "invalid" for n in demo.COLD_NIGHTS if n >= demo.BASELINE_NIGHTS)

    # nights judged against the first baseline keep the verdict line of their time
    def since(record):
        return record["verdict"].split("since the baseline of ")[1][:10]

    assert since(records[demo.BASELINE_NIGHTS]) < since(records[-1]) == since(tonight)
    warming = records[demo.COLD_NIGHTS[0]]["verdict"]
    assert "warming up" in warming, warming

    # every valid night's diagnostics; the X backlash wears 1 µm a week (a trend the
    # diagnostics see night by night) and its own alarm fires while the squareness is ok
    backlash = [
        (i, r["diagnostics"]["backlash_x"]) for i, r in enumerate(records) if r["diagnostics"]
    ]
    assert len(backlash) >= demo.NIGHTS - len(demo.COLD_NIGHTS)
    for i, b in backlash:
        worn = demo.BACKLASH_X_UM + demo.BACKLASH_WEAR_UM_PER_WEEK * i / 7
        assert b["value"] == pytest.approx(worn, abs=0.2), (i, b)
    fired = [i for i, r in enumerate(records) if "backlash_x" in r["diagnostic_alarms"]]
    assert fired and states[fired[0]] == "ok"
    assert "backlash_x" in tonight["diagnostic_alarms"]
    # the verdict line the README shows is of tonight's form (a standing alarm adds its date)
    shown = re.search(r"^    (demo-mill: .*)$", README.read_text("utf-8"), re.M).group(1)
    line = f"{tonight['machine_id']}: {tonight['verdict']}"
    line = re.sub(r" \(alarm since \d{4}-\d\d-\d\d, until a new baseline is set\)", "", line)
    if tonight["state"] == "ok":
        assert form_of(shown).fullmatch(line), (shown, line)
    assert (data / f"{demo.MACHINE_ID}-diagnostics.png").stat().st_size > 10_000
