"""A night with samples lost on the link is judged, not thrown away.

The monitor records through a real pseudo-terminal from the emulated board,
as a shop's nightly job does. A link with light byte errors loses a few dozen
samples in short gaps: the analysis bridges them, so the night is judged and
what it lost is noted with it; before, every such night was stored invalid.
"""

import json

from acq_board import PROGRAM, running_board

from imu_square.cli import main
from imu_square.monitor.history.store import open_history

MONITOR = """\
[monitor]
machine_id = "m1"
history = "history.db"
data_dir = "data"

[sensor]
port = "{port}"
trigger = "motion"

[program]
file = "{program}"

[analysis]
bootstrap = 0

[alarms]
monte_carlo_nights = 200000
"""


def night(folder, capsys, seed, faults=""):
    """One ``nightly --config --json`` night through the board: exit code and record."""
    with running_board(folder, faults=faults, seed=seed):
        code = main(["nightly", "--config", str(folder / "monitor.toml"), "--json"])
    return code, json.loads(capsys.readouterr().out.strip().splitlines()[-1])


def test_a_night_with_a_few_lost_samples_is_judged_and_says_what_it_lost(tmp_path, capsys):
    (tmp_path / "program.toml").write_text(PROGRAM.to_toml())
    (tmp_path / "monitor.toml").write_text(
        MONITOR.format(port=tmp_path / "board", program=tmp_path / "program.toml")
    )
    for seed in (1, 2, 3):
        code, record = night(tmp_path, capsys, seed)
        assert record["state"] == "no_baseline", record
    with open_history(tmp_path / "history.db") as history:
        runs = [str(r.id) for r in history.runs("m1")]
    assert main(["baseline", "set", "--config", str(tmp_path / "monitor.toml"), *runs]) == 0
    capsys.readouterr()
    code, record = night(tmp_path, capsys, 4, faults="corrupt=1e-4,drop=5e-5,garbage=1")
    assert record["state"] in ("ok", "warning"), record
    assert code in (0, 10)
    lost = [w for w in record["warnings"] if "samples lost" in w]
    assert lost, record["warnings"]
    assert "samples lost in" in record["reason"], record["reason"]
