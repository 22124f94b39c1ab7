"""The docs pages generated from sources (launch_scripts/docs.py) are current and complete:
docs/interfaces.md from msg/ (msg/reference.py), docs/python-api.md from sorting_line_gym
(bridge/api_reference.py), and the topic table of README.md and docs/ros-node.md from the topic
vocabulary (bridge/topics_reference.py)."""

from __future__ import annotations

import importlib.util
import subprocess
import sys

from support import ros_harness as h


def _load(path):
    spec = importlib.util.spec_from_file_location(f"docs_{path.stem}", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # (its dataclasses look their module up)
    spec.loader.exec_module(module)
    return module


def test_the_generated_pages_are_current():
    proc = subprocess.run(
        [sys.executable, str(h.ROOT / "launch_scripts" / "docs.py"), "--check"], capture_output=True, text=True
    )
    assert proc.returncode == 0, proc.stderr


def test_every_interface_definition_and_field_is_on_its_page():
    reference = _load(h.ROOT / "msg" / "reference.py")
    page = (h.ROOT / "docs" / "interfaces.md").read_text()
    definitions = sorted(p for p in (h.ROOT / "msg").rglob("*") if p.suffix in (".msg", ".srv", ".action"))
    assert len(definitions) >= 21
    for path in definitions:
        package = "simulation_interfaces" if "simulation_interfaces" in path.parts else "sorting_line_interfaces"
        assert f"### {package}/{path.parent.name}/{path.stem}\n" in page, path
        for part in reference.parse(path)[1]:
            for item in part.items:
                if isinstance(item, reference.Field):
                    assert f"| `{item.name}` | `{item.type}` |" in page, f"{path.name}: {item.name}"


def test_every_python_module_is_on_its_page_in_a_layer():
    reference = _load(h.ROOT / "bridge" / "api_reference.py")
    page = (h.ROOT / "docs" / "python-api.md").read_text()
    paths = reference.modules()
    assert len(paths) == len(list(reference.PACKAGE.rglob("*.py"))) > 50
    for path in paths:
        name = ".".join(["sorting_line_gym", *path.relative_to(reference.PACKAGE).with_suffix("").parts])
        assert f"### `{name.removesuffix('.__init__')}`\n" in page, name


def test_the_topic_tables_are_the_vocabularys():
    """README.md and docs/ros-node.md hold the same table, with a row naming every endpoint."""
    reference = _load(h.ROOT / "bridge" / "topics_reference.py")
    block = reference.render()
    for page in reference.PAGES:
        assert block in page.read_text(), page
    for endpoint in reference.vocabulary().ENDPOINTS:
        assert f"`{'~/' if endpoint.scope == 'private' else ''}{endpoint.name}`" in block, endpoint.name
