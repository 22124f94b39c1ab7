"""The transfer study's scenarios (studies/transfer_cells.py SCENARIOS, evolutions/*.yaml) without a
node or a training: each ready schedule loads and passes the library's validation (a bad one is
refused), the lines before and after each change are what the library's evolving line runs, the
baselines cell has random and the oracle on both sides of every change (the oracle of the fixed
line with that side's dynamics, and none where random's episodes there differ from the schedule's),
rba and rba-hold on a paper setup where a side is one, the first version's schedules keep their
digests (so its stores stay valid), a store of that version refuses the newer scenarios naming the
allowed ones and has its baselines cells redone, and an unknown scenario, a bad seed list or a bad
argument of the offline evaluation fails at the start naming the allowed ones.

The baselines cell runs the library's evaluation in this process (a second or two per scenario).
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

#: (paper line before the change, paper line after it): where rba and rba-hold run on a paper setup.
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


def baselines(scenario: str, out) -> dict:
    tc.schedules(scenario, 10, out)
    changed = tc.schedule_paths(scenario, 10, out)[1]
    return tc.run_baselines(
        tc.Cell(scenario, "baselines"), tc.Settings(10, 10, 3), changed, tc.before_path(scenario, out)
    )


@pytest.mark.parametrize("scenario", tc.SCENARIOS)
def test_the_baselines_cell_has_random_and_the_oracle_on_both_sides(scenario, tmp_path):
    """The oracle solves each side's fixed line, which random's episodes show to be that side's
    line; where a side is a paper setup it is that setup's oracle, and rba runs on that setup."""
    record = baselines(scenario, tmp_path)
    assert "oracle_before_missing" not in record and "oracle_after_missing" not in record
    for side, paper in zip(("before", "after"), PAPER_LINES[scenario], strict=True):
        assert set(record[side]) == {"rba", "rba-hold", "random", "oracle"} and all(
            len(v) == 3 for v in record[side].values()
        )
        assert min(record[side]["oracle"]) > max(record[side]["random"]), side
        if paper is not None:
            assert record[side]["oracle"] == tc.library("oracle", None, paper[1], 3, setup=paper[0]), side
    if PAPER_LINES[scenario][0] is not None:
        setup, variant = PAPER_LINES[scenario][0]
        assert record["before"]["rba"] == tc.library("eval", "rba", variant, 3, setup=setup)


def test_a_fixed_line_whose_random_episodes_differ_gets_no_oracle(tmp_path, monkeypatch):
    """The guard: an oracle of another line (here one with threshold 0.8 for drift's line before
    it changes, whose threshold is 0.7) is left out, saying why."""
    fixed = tc.fixed_line
    monkeypatch.setattr(tc, "fixed_line", lambda state: {**fixed(state), "threshold": 0.8})
    record = baselines("drift", tmp_path)
    assert "oracle" not in record["before"] and "oracle" in record["after"]  # drift ends at threshold 0.8
    assert "random's episodes on the fixed line" in record["oracle_before_missing"]
    assert "drift-before.yaml" in record["oracle_before_missing"]


def test_the_offline_evaluation_names_the_allowed_values():
    with pytest.raises(ValueError, match="setup = 'E' is not valid: allowed A, B, C, D"):
        tc.library("eval", "rba", "advanced", 1, setup="E")
    with pytest.raises(ValueError, match="variant = 'extended' is not valid: allowed basic, advanced"):
        tc.library("eval", "rba", "extended", 1)
    with pytest.raises(ValueError, match="command = 'optimum' is not valid: allowed eval, oracle"):
        tc.library("optimum", None, "advanced", 1)
    with pytest.raises(ValueError, match="cannot solve an evolving one"):
        tc.rewards("oracle", None, {"evolution": "upgrade.yaml"}, 1)


def test_an_algorithm_the_study_does_not_train_is_refused():
    # Once, anything but "ppo" became A2C here.
    for build in (tc.hyperparameters, tc.algorithm_class):
        with pytest.raises(ValueError, match="algo = 'dqn' is not valid: allowed ppo, a2c"):
            build("dqn")


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


def test_a_baselines_cell_of_the_first_version_is_redone_and_the_others_are_kept(tmp_path, capsys):
    """The first version's baselines cell recorded no random: the study runs it again (offline,
    seconds), with the cell's name and why; --report-only leaves it as it is."""
    args = transfer.options(["--smoke", "--scenarios", "upgrade", "--out", str(tmp_path)])
    store = CellStore(tmp_path, args.settings.key(scenarios=tc.FIRST_SCENARIOS))
    store.begin(["a study of the first version"])
    sides = {side: {"rba": [1.0] * 3, "rba-hold": [2.0] * 3, "oracle": [3.0] * 3} for side in ("before", "after")}
    old = {"cell": {"scenario": "upgrade", "kind": "baselines", "algo": None, "seed": None}, **sides, "seconds": 0.1}
    store.save("upgrade_baselines", old)
    assert tc.outdated(store.load("upgrade_baselines"))
    # A trained cell with its evaluations before the change is kept (without them: test_shrink_perturb.py).
    assert not tc.outdated({"cell": {"kind": "transfer"}, **{k: [] for k in tc.BEFORE_EVALUATIONS["transfer"]}})
    argv = ["--smoke", "--scenarios", "upgrade", "--out", str(tmp_path)]
    assert transfer.main([*argv, "--report-only"]) == 0
    assert "no AUC: the baselines cell has no random after the change" in (tmp_path / "transfer.md").read_text()
    assert "first version" not in capsys.readouterr().err
    assert transfer.main([*argv, "--max-cells", "1"]) == 0
    assert "upgrade_baselines: a baselines cell of the study's first version" in capsys.readouterr().err
    redone = store.load("upgrade_baselines")
    assert redone is not None and not tc.outdated(redone) and redone["invocation"] == 2
    assert "AUC normalised between random and the oracle" in (tmp_path / "transfer.md").read_text()


def test_an_unknown_scenario_fails_at_the_start_naming_the_allowed_ones(tmp_path, capsys):
    with pytest.raises(SystemExit) as exit_:
        transfer.main(["--scenarios", "upgrade", "flood", "--out", str(tmp_path / "t")])
    err = capsys.readouterr().err
    assert exit_.value.code == 2 and "invalid choice: 'flood'" in err
    assert all(s in err for s in tc.SCENARIOS)
    assert not (tmp_path / "t").exists()
    with pytest.raises(ValueError, match="scenario = 'flood' is not valid: allowed upgrade, drift, sensor"):
        tc.line_states("flood")


@pytest.mark.parametrize("seeds", [["1", "2", "1"], ["-1"]])
def test_a_bad_seed_list_fails_at_the_start(seeds, tmp_path, capsys):
    with pytest.raises(SystemExit) as exit_:
        transfer.main(["--seeds", *seeds, "--out", str(tmp_path / "t")])
    err = capsys.readouterr().err
    assert exit_.value.code == 2 and f"--seeds {' '.join(seeds)} is not valid: allowed distinct training seeds" in err
    assert not (tmp_path / "t").exists()
