"""The README runs as written: its Python blocks, its commands, its example, its output names.

Every ```` ```python ```` block of README.md runs on its own, from a file in a temporary folder
(Warp reads a kernel's source from its file), with two things provided:

* a hidden preamble (:data:`PREAMBLE`) defining what the blocks take from the reader's own code:
  ``meshes`` (two crossing cubes), ``transforms`` (their rigid poses), ``lower`` and ``upper``
  (``(N, 3)`` box corners, some overlapping); and in the folder, ``anim.usd``, the test stages'
  mixed animation (rigid, deforming and instanced prims, 24 time codes);
* the substitutions of :data:`SUBSTITUTIONS`, which keep the README's sizes and device for the
  reader and make them small and CPU-bound here: ``"cuda:0"`` becomes the test device, 1,000
  objects 30 and 120 frames 3. Each must occur in the README (a stale one fails the test).

The commands: every ``python`` the README tells one to run is the project's
``.venv/bin/python`` (it runs without activating the environment), and every example it names
exists. The USD check example runs as the README gives it, from the repository root, with its
exit status 1 (it builds penetrations on purpose) explained and its temporary folder removed.
"""

import os
import re
import runpy
import shutil
import subprocess
import sys

import numpy as np
import pytest

from conftest import DEFAULT_DEVICE

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
README = os.path.join(ROOT, "README.md")

SUBSTITUTIONS = {
    '"cuda:0"': lambda device: repr(device),
    "num_objects=1000": lambda device: "num_objects=30",
    "range(120)": lambda device: "range(3)",
}
"""README text -> what the test runs instead (given the test device)."""

PREAMBLE = {
    "meshes": "two unit cubes, the second moved by 0.5 on every axis: they cross",
    "transforms": "(2, 4, 4) rigid transforms of them (identity, then a shift by -0.25: they still cross)",
    "lower": "(5, 3) float32 lower box corners",
    "upper": "(5, 3) float32 upper box corners (boxes 0-1 and 3-4 overlap)",
}
"""What the preamble defines for the blocks (see :func:`preamble`)."""


def readme() -> str:
    with open(README, encoding="utf-8") as fh:
        return fh.read()


def python_blocks(text: str) -> list[str]:
    return re.findall(r"^```python\n(.*?)^```", text, flags=re.S | re.M)


def preamble() -> dict:
    """The namespace every block starts from (:data:`PREAMBLE`)."""
    import warp_ccd as wc

    v, t = wc.scene.shape("cube")
    v = (np.sign(v).astype(np.float64) + 1.0) / 2.0  # the unit cube [0, 1]^3
    moved = (v + 0.5, t)
    transforms = np.tile(np.eye(4), (2, 1, 1))
    transforms[1, :3, 3] = -0.25  # the second cube at 0.25: they still cross
    lower = np.array([[0, 0, 0], [0.5, 0.5, 0.5], [3, 3, 3], [6, 0, 0], [6.9, 0, 0]], np.float32)
    upper = lower + 1.0
    ns = {"meshes": [(v, t), moved], "transforms": transforms, "lower": lower, "upper": upper}
    assert set(ns) == set(PREAMBLE)
    return ns


def test_readme_python_blocks_run(tmp_path, monkeypatch):
    pytest.importorskip("pxr")
    from usd_stages import mixed_stage

    text = readme()
    blocks = python_blocks(text)
    assert len(blocks) >= 2, "the API block and the USD check block"
    for old in SUBSTITUTIONS:
        assert any(old in b for b in blocks), f"substitution {old!r} matches no README block"
    stage = mixed_stage(tmp_path / "anim.usd", num_frames=24)
    del stage
    monkeypatch.chdir(tmp_path)
    uses_usd = False
    for k, block in enumerate(blocks):
        code = block
        for old, new in SUBSTITUTIONS.items():
            code = code.replace(old, new(DEFAULT_DEVICE))
        path = tmp_path / f"readme_block_{k}.py"
        path.write_text(code)
        try:
            ns = runpy.run_path(str(path), init_globals=preamble(), run_name=f"readme_block_{k}")
        except Exception as exc:
            raise AssertionError(f"README python block {k} failed: {type(exc).__name__}: {exc}\n{block}") from exc
        if "hit" in ns:  # the kernel of one's own: the two triangles cross
            assert ns["hit"].numpy().tolist() == [1]
        if "swept" in ns:  # the continuous example: the box reaches the wall at (1 - 0.1 / sqrt(3)) / 2, never later
            assert ns["swept"].object_pairs.tolist() == [[0, 1]]
            assert 0.4711 < ns["swept"].toi <= (1 - 0.1 / np.sqrt(3)) / 2
            assert ns["hits"].tolist() == [True] and 0.4999 < ns["tois"][0] <= 0.5
        if "report" in ns:
            uses_usd = True
            assert ns["report"].penetrating and len(ns["report"].frames) == 24
    assert uses_usd, "a block checks anim.usd"
    assert (tmp_path / "out.usd").exists()


def test_readme_commands_use_the_venv():
    text = readme()
    commands = re.findall(r"`([^`\n]*\bpython3?\b[^`\n]*)`", text)
    for block in re.findall(r"^```(?:bash|sh)?\n(.*?)^```", text, flags=re.S | re.M):
        commands += [line for line in block.splitlines() if re.search(r"\bpython3?\b", line)]
    assert commands
    for command in commands:
        for part in re.split(r"&&|;|\|", command):
            words = part.split()
            if not words or not re.fullmatch(r"(\S*/)?python3?", words[0]):
                continue
            if words[:3] == ["python3", "-m", "venv"]:  # making the environment
                continue
            assert words[0] == ".venv/bin/python", f"README runs {part.strip()!r}: use .venv/bin/python"
            if len(words) > 1 and words[1].endswith(".py"):
                assert os.path.isfile(os.path.join(ROOT, words[1])), f"README names a missing {words[1]}"


def test_readme_outputs_are_ignored_by_git():
    if shutil.which("git") is None or subprocess.run(["git", "rev-parse", "--git-dir"], cwd=ROOT,
                                                     capture_output=True).returncode != 0:
        pytest.skip("not a git checkout")
    text = readme()
    names = ["report.json", "overlay.usda", "worst.png", "preview.png", "collisions.usd", "out.usd"]
    for name in names:
        assert name in text
    proc = subprocess.run(["git", "check-ignore", "--no-index", *names], cwd=ROOT, capture_output=True, text=True)
    assert sorted(proc.stdout.split()) == sorted(names), f"not ignored: {set(names) - set(proc.stdout.split())}"


def test_usd_check_example_as_the_readme_runs_it(tmp_path):
    """``.venv/bin/python examples/example_usd_check.py`` from the repository root, without an
    activated environment: exit status 1, explained, and no temporary folder left behind."""
    pytest.importorskip("pxr")
    command = re.search(r"`(\S*python\S* examples/example_usd_check\.py)`", readme())
    assert command, "the README gives the USD check example's command"
    python, script = command.group(1).split()
    python = os.path.join(ROOT, python) if os.path.exists(os.path.join(ROOT, python)) else sys.executable
    temp = tmp_path / "tmp"
    temp.mkdir()
    env = {k: v for k, v in os.environ.items() if k not in ("VIRTUAL_ENV", "PYTHONPATH", "PYTHONHOME")}
    env.update(TMPDIR=str(temp), TEMP=str(temp), TMP=str(temp))
    if python == sys.executable:  # no .venv here: the package (and what this Python imports) must still be found
        env["PYTHONPATH"] = os.pathsep.join(p for p in (ROOT, os.environ.get("PYTHONPATH")) if p)
    proc = subprocess.run([python, script, "--device", DEFAULT_DEVICE, "--num-frames", "8"], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 1, proc.stderr
    assert "exit status 1" in proc.stdout and "on purpose" in proc.stdout, proc.stdout
    assert list(temp.iterdir()) == [], "the example left its temporary folder"
