"""Bags recorded by others: `sorting-line-bag info`, `replay` and `check` on bags written the way
`ros2 bag record -a` writes them in a ROS 2 graph (tests/python/support/ros2_bags.py: rosbags' writer,
rosbag2 version 9 metadata, MCAP and sqlite3 storage, no custom_data of ours, extra topics, one
of a type this project does not know, the line in another namespace), from the golden bags' data.

- `info` names the line, each option the bag tells with its source (/diagnostics, the states,
  /parameter_events), the topics of unknown types, and the flags a replay still needs;
- `replay` of the MCAP bag (no /parameter_events of the node) names exactly the missing flags
  (exit 2), then with `--setup D` reproduces every message; the sqlite3 bag, whose recorder
  caught the node's parameters on /parameter_events (seed of line_2 = node seed + 2), replays
  with no flags at all;
- `play` leaves out /rosout, /parameter_events and the unknown type;
- open-loop `check` of `sorting-line-controller` passes on both; closed-loop `check` of the MCAP
  bag names the missing flags (exit 2), then passes with `--setup D` (as `overrides`);
- a bag of nothing but other types is refused with the types named (exit 2).
"""

from __future__ import annotations

from pathlib import Path

import pytest

from sorting_line_gym.bag import open_bag
from sorting_line_gym.bag.cli import main
from sorting_line_gym.bag.transport.replay import replay
from support.bag_golden import DATA, GOLDEN
from support.ros2_bags import CELL_STATUS, write_ros2_bag

#: The node serving /plant/line_2 hosted three lines with seed 7: line 2 has seed 9, advanced_b's.
PLANT_PARAMETERS = {
    "variant": "advanced",
    "input": "seasonal",
    "obs_noise": 0.0,
    "action_penalty": 0.5,
    "threshold": 0.7,
    "max_steps": 50,
    "seed": 7,
    "mode": "lockstep",
    "lines": 3,
    "tick_period": 1.0,
    "rate": 10.0,
    "use_sim_time": False,
}


def _diagnostics_options(name: str) -> dict:
    spec = GOLDEN[name]
    return {"seed": spec["seed"], "variant": spec["variant"], "input": "seasonal", "mode": "lockstep"}


@pytest.fixture(scope="module")
def ros2_bags(tmp_path_factory) -> dict[str, Path]:
    """storage -> a bag of a golden bag's data as `ros2 bag record -a` writes it."""
    base = tmp_path_factory.mktemp("ros2_bags")
    return {
        "mcap": write_ros2_bag(
            DATA / "basic_d", base / "cell_3", "mcap", "/factory/cell_3", _diagnostics_options("basic_d")
        ),
        "sqlite3": write_ros2_bag(
            DATA / "advanced_b",
            base / "plant",
            "sqlite3",
            "/plant/line_2",
            _diagnostics_options("advanced_b"),
            node_parameters=PLANT_PARAMETERS,
        ),
    }


pytestmark = pytest.mark.usefixtures("same_binary")  # conftest: the tools start the tests' binary


def test_info_tells_the_line_and_where_each_option_came_from(ros2_bags, capsys):
    assert main(["info", str(ros2_bags["mcap"])]) == 0
    out = capsys.readouterr().out
    cell = next(line for line in out.splitlines() if "/factory/cell_status" in line)
    assert CELL_STATUS in cell and "type not known here" in cell, out
    assert "line /factory/cell_3 (recorded by another tool" in out, out
    for told in (
        "variant=basic (/diagnostics)",
        "seed=5 (/diagnostics)",
        "max_steps=50 (states)",
        "tick_period=1.0 (states)",
        "input=seasonal (/diagnostics)",
    ):
        assert told in out, out
    assert "not in the bag: obs_noise, action_penalty, threshold" in out, out

    assert main(["info", str(ros2_bags["sqlite3"])]) == 0
    out = capsys.readouterr().out
    assert "line /plant/line_2 (recorded by another tool" in out and "not in the bag" not in out, out
    # The line's node announced seed 7 for its three lines: line_2's is 9. The controller's own
    # announcement (variant "basic" too) is not the line's node's.
    assert "seed=9 (/parameter_events)" in out and "variant=advanced (/parameter_events)" in out, out
    bag = open_bag(ros2_bags["sqlite3"])
    assert bag.path.joinpath("plant_0.db3").is_file() and bag.info.node["seed"] == GOLDEN["advanced_b"]["seed"]


def test_replay_names_the_missing_flags_then_reproduces_the_bag(ros2_bags, capsys):
    assert main(["replay", str(ros2_bags["mcap"])]) == 2
    err = capsys.readouterr().err
    assert (
        "does not say the node's obs_noise, action_penalty, threshold: pass --obs-noise ... "
        "--action-penalty ... --threshold ... (--setup A|B|C|D gives" in err
    ), err
    result = replay(ros2_bags["mcap"], {"setup": GOLDEN["basic_d"]["setup"]})
    assert result.identical, result.report()
    assert result.comparison.compared["state"] == 255 and result.resets == 5, result.report()


def test_a_bag_with_the_nodes_parameters_replays_with_no_flags(ros2_bags):
    result = replay(ros2_bags["sqlite3"])
    assert result.identical, result.report()
    assert result.options["seed"] == 9 and result.comparison.compared["sensors/ratio"] == 255, result.report()


def test_a_bag_of_other_types_only_is_refused(tmp_path, capsys):
    from rosbags.rosbag2 import StoragePlugin, Writer

    from support.ros2_bags import user_typestore

    store = user_typestore()
    writer = Writer(tmp_path / "other", version=9, storage_plugin=StoragePlugin.MCAP)
    writer.open()
    c = writer.add_connection("/factory/cell_status", CELL_STATUS, typestore=store)
    writer.write(c, 1, bytes(store.serialize_cdr(store.types[CELL_STATUS](cell="a", temperature=1.0), CELL_STATUS)))
    writer.close()
    assert main(["info", str(tmp_path / "other")]) == 2
    err = capsys.readouterr().err
    assert f"message types this tool does not know: {CELL_STATUS} (and no sorting line's state topic)" in err, err


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_open_loop_check_passes_the_controller_that_drove_the_line(ros2_bags, storage):
    """The bag's node side played tick by tick in its own namespace to `sorting-line-controller`:
    its answers are the recorded ones (the extra topics are neither played nor in the way)."""
    from sorting_line_gym.bag.check.checker import check_controller

    name = "basic_d" if storage == "mcap" else "advanced_b"
    spec = GOLDEN[name]
    verdict = check_controller(
        ros2_bags[storage],
        controller=f"sorting-line-controller --setup {spec['setup']} "
        f"--variant {spec['variant']} --agent {spec['agent']}",
    )
    assert verdict.passed and verdict.exit_code == 0, verdict.summary()
    assert verdict.namespace == ("/factory/cell_3" if storage == "mcap" else "/plant/line_2"), verdict.summary()
    assert verdict.count("matching") >= 250 and not verdict.differences, verdict.summary()


def test_closed_loop_check_names_the_missing_flags_then_passes_with_them(ros2_bags):
    from sorting_line_gym.bag.check.checker import check_controller

    spec = GOLDEN["basic_d"]
    verdict = check_controller(ros2_bags["mcap"], closed_loop=True, wait=1.0)
    assert verdict.exit_code == 2, verdict.summary()
    assert "pass --obs-noise ... --action-penalty ... --threshold ... (--setup A|B|C|D" in verdict.error, verdict.error
    verdict = check_controller(
        ros2_bags["mcap"],
        closed_loop=True,
        overrides={"setup": spec["setup"]},
        controller=f"sorting-line-controller --setup {spec['setup']} --agent {spec['agent']}",
    )
    assert verdict.passed and len(verdict.episodes) == 5, verdict.summary()


def test_play_leaves_out_the_recorded_graphs_own_topics(ros2_bags, capsys):
    assert main(["play", str(ros2_bags["mcap"]), "--rate", "0", "--no-wait", "--namespace", "/elsewhere"]) == 0
    out = capsys.readouterr().out
    # 255 ticks of input, belt/occupancy, state and /clock, 5 resets, 1 /diagnostics; not the commands
    assert "played 1026 messages" in out and "/elsewhere/state 255" in out, out
    assert (
        "not played: /factory/cell_status (type factory_msgs/msg/CellStatus not known here), /parameter_events "
        "(the recorded nodes' own topic), /rosout (the recorded nodes' own topic)"
    ) in out, out
