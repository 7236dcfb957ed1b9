"""trimesh's own collision tests, unchanged, against warp_ccd.trimesh.CollisionManager.

Exports ``tests/`` and ``models/`` of a trimesh checkout (``git archive``, any commit) into a temporary folder
(with an empty ``models/2D`` where the export has none: ``tests/generic.py`` lists it), drops a ``conftest.py``
into its ``tests/`` that puts warp_ccd's ``CollisionManager`` and ``scene_to_collision`` in place of
``trimesh.collision``'s, and runs ``pytest tests/test_collision.py`` there with the installed trimesh and this
repository's warp_ccd first on the path. ``--stock`` runs the same tests on trimesh's own (FCL) manager instead,
for comparison. Prints pytest's report and, with ``--out``, writes each test's outcome as JSON.

``test_scene`` loads a ``.3DXML``, which needs lxml (with stock FCL too): ``--path DIR`` puts a folder holding it
(``pip install --target DIR lxml``) on the tests' path without installing it anywhere else.

    python -m bench.trimesh_upstream --path /tmp/lxml_site --out bench/results/trimesh_upstream.json
"""

from __future__ import annotations

import argparse
import io
import json
import os
import subprocess
import sys
import tarfile
import tempfile
import xml.etree.ElementTree as ET
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
"""This repository: its warp_ccd goes first on the tests' path."""

DEFAULT_CHECKOUT = "/work/.mirror/mikedh+trimesh/repo"

CONFTEST = '''"""Written by warp_ccd's bench/trimesh_upstream.py: trimesh.collision's manager replaced by warp_ccd's."""

import trimesh.collision
import warp

from warp_ccd.trimesh import CollisionManager, scene_to_collision

trimesh.collision.CollisionManager = CollisionManager
trimesh.collision.scene_to_collision = scene_to_collision
warp.config.quiet = True  # no line for each module Warp loads
'''


def export(checkout: str, ref: str, folder: Path) -> str:
    """Writes ``tests/`` and ``models/`` of ``ref`` in the git repository ``checkout`` (a work tree or a bare
    repository) under ``folder``; returns the commit's hash."""
    commit = subprocess.run(["git", "-C", checkout, "rev-parse", ref], check=True, capture_output=True,
                            text=True).stdout.strip()
    tar = subprocess.run(["git", "-C", checkout, "archive", "--format=tar", commit, "tests", "models"], check=True,
                         capture_output=True).stdout
    with tarfile.open(fileobj=io.BytesIO(tar)) as archive:
        archive.extractall(folder, filter="data")
    (folder / "models" / "2D").mkdir(parents=True, exist_ok=True)
    return commit


def outcomes(junit: Path) -> dict[str, dict]:
    """``{test name: {"outcome": passed | failed | error | skipped, "message": pytest's first line, "line": the
    statement that failed}}`` (None where it passed) from pytest's JUnit XML report."""
    out = {}
    for case in ET.parse(junit).getroot().iter("testcase"):
        bad = [child for child in case if child.tag in ("failure", "error", "skipped")]
        outcome = {"failure": "failed", "error": "error", "skipped": "skipped"}[bad[0].tag] if bad else "passed"
        message = (bad[0].get("message") or "").splitlines()[0] if bad and bad[0].get("message") else None
        failing = [line[1:].strip() for line in (bad[0].text or "").splitlines() if line.startswith(">")] if bad else []
        out[case.get("name")] = {"outcome": outcome, "message": message, "line": failing[-1] if failing else None}
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trimesh", default=DEFAULT_CHECKOUT, help="a trimesh git checkout (default: %(default)s)")
    parser.add_argument("--ref", default="HEAD", help="the commit of its tests (default: HEAD)")
    parser.add_argument("--stock", action="store_true", help="trimesh's own FCL manager, not warp_ccd's")
    parser.add_argument("--path", action="append", default=[], help="a folder put on the tests' path (lxml)")
    parser.add_argument("--out", default=None, help="JSON file of the outcomes (default: none)")
    parser.add_argument("pytest_args", nargs="*", help="more arguments for pytest (after --)")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="trimesh_upstream_") as tmp:
        folder = Path(tmp)
        commit = export(args.trimesh, args.ref, folder)
        if not args.stock:
            (folder / "tests" / "conftest.py").write_text(CONFTEST)
        env = dict(os.environ)
        env["PYTHONPATH"] = os.pathsep.join([str(ROOT), *args.path, *filter(None, [env.get("PYTHONPATH")])])
        junit = folder / "report.xml"
        rc = subprocess.run([sys.executable, "-m", "pytest", "tests/test_collision.py", "-v", "-rA",
                             "-p", "no:cacheprovider", f"--junitxml={junit}", *args.pytest_args],
                            cwd=folder, env=env).returncode
        found = outcomes(junit) if junit.exists() else {}
    manager = "trimesh (python-fcl)" if args.stock else "warp_ccd.trimesh"
    print(f"trimesh {commit[:12]} tests/test_collision.py on {manager}: "
          + ", ".join(f"{name} {state['outcome']}" for name, state in found.items()))
    if args.out:
        Path(args.out).write_text(json.dumps({"trimesh_commit": commit, "manager": manager, "path": args.path,
                                              "pytest_status": rc, "tests": found}, indent=1) + "\n")
    return rc


if __name__ == "__main__":
    sys.exit(main())
