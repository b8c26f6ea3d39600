"""Writes docs/scene-format.md from the scene schema (gpiscl/host/scene/reference.py).

    python tools/make_scene_reference.py
"""
from pathlib import Path

from gpiscl.host.scene.reference import scene_reference

OUT = Path(__file__).resolve().parent.parent / "docs" / "scene-format.md"

if __name__ == "__main__":
    OUT.write_text(scene_reference())
    print(f"wrote {OUT}")
