"""The README runs as written: its Python blocks, its commands, its example, its links, its size.

Every ```` ```python ```` block of README.md runs as it stands, as a reader pastes it on a machine without a
GPU: nothing is defined for it, nothing in it is replaced, and no block names a CUDA device (each takes
Warp's default device: the GPU where there is one, else the CPU). The blocks run one after the other in one
temporary folder, each from a file of its own (Warp reads a kernel's source from its file); what they
print is checked where it is the point of the block.

The commands: every ``python`` the README tells one to run is the project's ``.venv/bin/python`` (it
runs without activating the environment), every example it names exists, and the commands CI runs
(``.ci/run``) are the ones the README gives. The USD check example runs as the README gives it, from the
repository root, with its exit status 1 (it builds penetrations on purpose) explained and its temporary
folder removed. The README stays short (:data:`README_MAX_BYTES`), and its links name files that exist.
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

README_MAX_BYTES = 15 * 1024
"""What a newcomer reads: the rest is on the documentation site (``docs/site/``)."""

CUDA_DEVICE = re.compile(r"""["']cuda(:\d+)?["']""")
"""A string naming a CUDA device (``"cuda:0"``): a block that names one would not run as pasted on a machine
without a GPU."""


def readme() -> str:
    with open(README, encoding="utf-8") as fh:
        return fh.read()


def python_blocks(text: str) -> list[str]:
    """The code of every ```` ```python ```` block of a Markdown text (whatever follows ``python`` on the
    fence line, such as markdown-exec's ``exec="on"``), in order."""
    return re.findall(r"^```python[^\n]*\n(.*?)^```", text, flags=re.S | re.M)


def run_blocks(blocks: list[str], folder, name: str) -> list[dict]:
    """Runs ``blocks`` one after the other as files of ``folder`` (the current directory), each in a fresh
    namespace (``name_block_k``, a module name of its own for Warp), and returns their namespaces. A block
    that fails raises an AssertionError naming it and showing its code."""
    namespaces = []
    for k, block in enumerate(blocks):
        assert not CUDA_DEVICE.search(block), f"{name} block {k} names a CUDA device: it must run on the CPU\n{block}"
        path = folder / f"{name}_block_{k}.py"
        path.write_text(block)
        try:
            namespaces.append(runpy.run_path(str(path), run_name=f"{name}_block_{k}"))
        except Exception as exc:
            raise AssertionError(f"{name} python block {k} failed: {type(exc).__name__}: {exc}\n{block}") from exc
    return namespaces


def test_readme_is_short():
    size = len(readme().encode("utf-8"))
    assert size <= README_MAX_BYTES, f"README.md is {size} bytes: move the detail to a page of docs/site/"


def test_readme_python_blocks_run_as_pasted(tmp_path, monkeypatch):
    pytest.importorskip("pxr")
    blocks = python_blocks(readme())
    assert len(blocks) >= 5, "the API tour: collide and the pipeline, continuous, clearance, the check, a kernel"
    monkeypatch.chdir(tmp_path)
    namespaces = run_blocks(blocks, tmp_path, "readme")
    found = set()
    for ns in namespaces:
        if "hit" in ns:  # the kernel of one's own: the two triangles cross
            assert ns["hit"].numpy().tolist() == [1]
            found.add("kernel")
        if "swept" in ns:  # the continuous example: the box reaches the wall at (1 - 0.1 / sqrt(3)) / 2, never later
            assert ns["swept"].object_pairs.tolist() == [[0, 1]]
            assert 0.4711 < ns["swept"].toi <= (1 - 0.1 / np.sqrt(3)) / 2
            assert ns["hits"].tolist() == [True] and 0.4999 < ns["tois"][0] <= 0.5
            found.add("continuous")
        if "far" in ns:  # clearance: the cubes 1.2 apart are 0.0453 apart; the far one 1.8453
            assert ns["far"].pairs.tolist() == [[0, 0]] and abs(ns["far"].distance[0] - (3 - 2 / np.sqrt(3))) < 1e-5
            found.add("clearance")
        if "report" in ns:
            assert ns["report"].penetrating and len(ns["report"].frames) == 24
            found.add("check")
        if "pipe" in ns and "meshes" in ns and "transforms" in ns:  # the spheres' frames: 1 has moved on to 2
            assert ns["pipe"].detect().object_pairs.tolist() == [[1, 2]]
            found.add("pipeline")
    assert found == {"kernel", "continuous", "clearance", "check", "pipeline"}, found
    assert (tmp_path / "collisions.usd").exists()


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


def test_ci_runs_what_the_readme_says():
    """``.ci/run`` installs and tests the project with the README's commands (its own venv's paths)."""
    with open(os.path.join(ROOT, ".ci", "run"), encoding="utf-8") as fh:
        ci = fh.read()
    text = readme()
    for command in ("python3 -m venv .venv", "-e '.[test]'", ".venv/bin/ruff check .", ".venv/bin/python -m pytest -q",
                    ".venv/bin/mkdocs build --strict"):
        assert command in text, f"the README does not say {command!r}"
        assert command in ci, f".ci/run does not run {command!r}, which the README says"
    assert re.search(r"pip install -e '\.\[test\]'", text) and re.search(r"pip install (-q )?-e '\.\[test\]'", ci)


def test_readme_links_name_files_that_exist():
    """Relative links and pictures of the README (``docs/site/...md``, ``docs/preview.png``, a plot of
    ``bench/results/``) name files of the repository: they work on GitHub, and the site serves them."""
    targets = re.findall(r"\]\(([^)\s]+)\)", readme())
    local = [t.split("#")[0] for t in targets if not re.match(r"[a-z][a-z0-9+.-]*:|#", t)]
    assert any(t.startswith("docs/site/") for t in local) and "docs/preview.png" in local
    missing = [t for t in local if not os.path.isfile(os.path.join(ROOT, t))]
    assert not missing, f"README links to files that do not exist: {missing}"


def test_readme_outputs_are_ignored_by_git():
    if shutil.which("git") is None or subprocess.run(["git", "rev-parse", "--git-dir"], cwd=ROOT,
                                                     capture_output=True).returncode != 0:
        pytest.skip("not a git checkout")
    text = readme()
    names = ["report.json", "overlay.usda", "worst.png", "preview.png", "collisions.usd"]
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
