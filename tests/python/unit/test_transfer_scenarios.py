"""The transfer study's scenarios (studies/transfer_cells.py SCENARIOS, evolutions/*.yaml) without a
node or a training: each ready schedule loads and passes the library's validation (a bad one is
refused), the lines before and after each change are what the library's evolving line runs, the
oracle is attached to the sides that are paper setups only, the first version's schedules keep
their digests (so its stores stay valid), a store of that version refuses the newer scenarios
naming the allowed ones, and an unknown scenario or a bad seed list fails at the start naming the
allowed ones.

The baselines cell runs the `sorting_line` binary offline (a few hundred milliseconds).
"""

from __future__ import annotations

import gymnasium
import pytest

import sorting_line_gym  # noqa: F401 - registers the ids
from sorting_line_gym.envs.evolving import READY_SCHEDULES
from sorting_line_gym.studies import transfer
from sorting_line_gym.studies import transfer_cells as tc
from sorting_line_gym.studies.cell_store import CellStore
from support.env_runs import EVOLVING

#: (paper line before the change, paper line after it): what the oracle can solve on each side.
PAPER_LINES = {
    "upgrade": (("B", "basic"), ("B", "advanced")),
    "drift": (("B", "advanced"), None),
    "sensor": (None, ("B", "advanced")),
    "machine": (None, ("B", "advanced")),
    "noise-drift": (("B", "advanced"), ("D", "advanced")),
    "threshold-drift": (("B", "advanced"), None),
    "setup-a-to-b": (("A", "advanced"), ("B", "advanced")),
}
#: The digests of the first version's schedules, in the key of every store written with them.
FIRST_DIGESTS = {"upgrade": "8553eb0cd63e4984", "drift": "b44b8540a7da41b6"}


def first_settings(schedule) -> dict:
    """The settings of the line's first episode on ``schedule``, as the library's evolving line has them."""
    env = gymnasium.make(EVOLVING, evolution=str(schedule), backend="native", max_episode_steps=1)
    try:
        return env.reset(seed=0)[1]["settings"]
    finally:
        env.close()


def test_every_scenario_is_a_ready_schedule_and_the_first_two_are_unchanged():
    assert set(tc.SCENARIOS) <= set(READY_SCHEDULES) and set(PAPER_LINES) == set(tc.SCENARIOS)
    assert tc.FIRST_SCENARIOS == ("upgrade", "drift") and tc.SCENARIOS[:2] == tc.FIRST_SCENARIOS
    assert {s: tc.schedule_digest(s) for s in tc.FIRST_SCENARIOS} == FIRST_DIGESTS
    assert all("_" not in s for s in tc.SCENARIOS), "a cell's name is split at '_' (transfer.kind_of)"


def test_a_schedule_the_library_refuses_is_refused(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("events:\n  - at: {episode: 0}\n    obs_noise: 7\n")
    with pytest.raises(ValueError, match="obs_noise = 7 is out of range"):
        first_settings(bad)


@pytest.mark.parametrize("scenario", tc.SCENARIOS)
def test_a_scenarios_lines_are_the_librarys(scenario, tmp_path):
    """The study's evolving schedule (the change at --before + 1) and the changed line's, validated
    by the library; their first episodes are ``line_states``'s before and after."""
    evolving, changed = tc.schedules(scenario, 10, tmp_path)
    before, after = tc.line_states(scenario)
    assert first_settings(evolving) == before and first_settings(changed) == after
    assert first_settings(tc.before_path(scenario, tmp_path)) == before
    assert before != after
    assert (tc.paper_line(before), tc.paper_line(after)) == PAPER_LINES[scenario]
    # The frozen snapshot is evaluated with the old machine's masks where the old machine had no modes.
    assert tc.frozen_mode0(scenario) == (scenario in ("upgrade", "machine"))


@pytest.mark.parametrize("scenario", ["sensor", "noise-drift", "threshold-drift"])
def test_the_baselines_cell_has_the_oracle_where_a_side_is_a_paper_setup(scenario, tmp_path):
    tc.schedules(scenario, 10, tmp_path)
    cell = tc.Cell(scenario, "baselines")
    changed = tc.schedule_paths(scenario, 10, tmp_path)[1]
    record = tc.run_baselines(cell, tc.Settings(10, 10, 3), changed, tc.before_path(scenario, tmp_path))
    before, after = PAPER_LINES[scenario]
    assert ("oracle" in record["before"]) == (before is not None) == ("oracle_before_missing" not in record)
    assert ("oracle" in record["after"]) == (after is not None) == ("oracle_after_missing" not in record)
    assert all(len(v) == 3 for side in ("before", "after") for v in record[side].values())
    assert set(record["after"]) >= {"rba", "rba-hold", "random"}
    if "oracle" in record["after"]:
        assert min(record["after"]["oracle"]) > max(record["after"]["random"])


def test_a_store_of_the_first_version_keeps_its_key_and_refuses_the_newer_scenarios(tmp_path, capsys):
    args = transfer.options(["--smoke", "--out", str(tmp_path)])
    old = args.settings.key(scenarios=tc.FIRST_SCENARIOS)
    CellStore(tmp_path, old).begin(["a study of the first version"])
    assert tc.key_scenarios(None, ["sensor"]) == tc.SCENARIOS
    assert tc.key_scenarios(old, ["upgrade"]) == tc.FIRST_SCENARIOS
    assert transfer.main(["--smoke", "--scenarios", "upgrade", "sensor", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "written before the scenarios sensor existed" in err and "allowed there --scenarios upgrade drift" in err
    # Its own scenarios: the key is accepted (nothing saved yet, so nothing to report).
    assert transfer.main(["--smoke", "--report-only", "--out", str(tmp_path)]) == 1
    assert "no finished cells to report" in capsys.readouterr().err
    # A new store keys every scenario's schedule.
    assert set(tc.Settings(10, 10, 3).key()["schedules"]) == set(tc.SCENARIOS)


def test_an_unknown_scenario_fails_at_the_start_naming_the_allowed_ones(tmp_path, capsys):
    with pytest.raises(SystemExit) as exit_:
        transfer.main(["--scenarios", "upgrade", "flood", "--out", str(tmp_path / "t")])
    err = capsys.readouterr().err
    assert exit_.value.code == 2 and "invalid choice: 'flood'" in err
    assert all(s in err for s in tc.SCENARIOS)
    assert not (tmp_path / "t").exists()
    with pytest.raises(ValueError, match="scenario = 'flood' is not known: allowed upgrade, drift, sensor"):
        tc.line_states("flood")


@pytest.mark.parametrize("seeds", [["1", "2", "1"], ["-1"]])
def test_a_bad_seed_list_fails_at_the_start(seeds, tmp_path, capsys):
    with pytest.raises(SystemExit) as exit_:
        transfer.main(["--seeds", *seeds, "--out", str(tmp_path / "t")])
    err = capsys.readouterr().err
    assert exit_.value.code == 2 and f"--seeds {' '.join(seeds)} is not valid: allowed distinct training seeds" in err
    assert not (tmp_path / "t").exists()
