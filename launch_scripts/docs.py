"""Writes the docs pages generated from the repository's sources, or checks that they are current.

    python3 launch_scripts/docs.py            # rewrite them
    python3 launch_scripts/docs.py --check    # exit 1 naming each stale page

The pages and their renderers (standard library only, so this runs before any set-up):
docs/interfaces.md from msg/'s definitions (msg/reference.py), docs/python-api.md from the source
of sorting_line_gym (bridge/api_reference.py); and a section of pages: the node's topic table in
README.md and docs/ros-node.md, between markers, from the topic vocabulary
(bridge/topics_reference.py). tests/python/unit/test_generated_docs.py checks the same.
"""

from __future__ import annotations

import argparse
import importlib.util
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RENDERERS = (ROOT / "msg" / "reference.py", ROOT / "bridge" / "api_reference.py")
#: Renderers of a section of pages: their PAGES, each rewritten by rewrite(text, page).
SECTIONS = (ROOT / "bridge" / "topics_reference.py",)


def load(path: Path):
    """A renderer module (its PAGE and render()), loaded from its file."""
    spec = importlib.util.spec_from_file_location(f"docs_{path.stem}", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # (dataclasses look their module up)
    spec.loader.exec_module(module)
    return module


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--check", action="store_true", help="exit 1 when a generated page is stale")
    args = parser.parse_args(argv)
    stale = []
    for renderer in map(load, RENDERERS):
        text, page = renderer.render(), Path(renderer.PAGE)
        if not args.check:
            page.write_text(text)
        elif not page.is_file() or page.read_text() != text:
            stale.append(page.relative_to(ROOT))
    for renderer in map(load, SECTIONS):
        for page in map(Path, renderer.PAGES):
            old = page.read_text()
            text = renderer.rewrite(old, page)
            if not args.check:
                page.write_text(text)
            elif old != text:
                stale.append(page.relative_to(ROOT))
    for page in stale:
        print(f"{page} is stale: run python3 launch_scripts/docs.py", file=sys.stderr)
    return 1 if stale else 0


if __name__ == "__main__":
    sys.exit(main())
