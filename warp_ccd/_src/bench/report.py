"""The scaling benchmark's report: what a result file records, its rows, tables, JSON and plot.

* :func:`environment`: where a result was measured (device, date, versions, git commit); the scaling
  benchmark records it (and so do the developers' benchmarks of ``bench/``, the repository's lab).
* :func:`write_json`: a result file, replaced in one step.
* :class:`BenchReport`: the scaling benchmark's cases (:class:`~warp_ccd._src.bench.methods.CaseResult`):
  a table per case and a summary on stdout (ratios are a peer's median over ``warp_ccd``'s for the
  same stage: above 1, ``warp_ccd`` is faster), the JSON document (its fields: see
  :mod:`warp_ccd._src.bench.scaling`) and a log-log plot of ms per frame against ``N`` (needs matplotlib).
"""

from __future__ import annotations

import datetime
import importlib.metadata
import json
import os
import platform
import subprocess
from pathlib import Path

import numpy as np
import warp as wp

from ..output import PendingFile, check_output_path, prepare_text
from .methods import REFERENCE, CaseResult

__all__ = ["JSON_EXTENSIONS", "PLOT_EXTENSIONS", "BenchReport", "environment", "git_commit", "write_json"]

JSON_EXTENSIONS = (".json",)
PLOT_EXTENSIONS = (".png", ".svg", ".pdf")

def _bytes(n: float | None) -> str:
    if n is None:
        return "-"
    for unit, size in (("GB", 1024**3), ("MB", 1024**2), ("KB", 1024)):
        if n >= size:
            return f"{n / size:.2f} {unit}"
    return f"{int(n)} B"


def git_commit() -> tuple[str | None, bool | None]:
    """``(commit, tracked files other than bench/results/ modified)`` of the code that runs: ``WARP_CCD_GIT_COMMIT`` and
    ``WARP_CCD_GIT_DIRTY`` ("0" or "1") from the environment when set (a copy of the tree on
    another machine, whose git, if any, need not describe it), else the checkout's HEAD, else Nones."""
    if os.environ.get("WARP_CCD_GIT_COMMIT"):
        dirty = os.environ.get("WARP_CCD_GIT_DIRTY")
        return os.environ["WARP_CCD_GIT_COMMIT"], (None if dirty is None else dirty == "1")
    root = Path(__file__).resolve().parents[3]  # warp_ccd/_src/bench/report.py: the checkout
    try:
        commit = subprocess.run(["git", "rev-parse", "HEAD"], cwd=root, capture_output=True, text=True, timeout=10)
        if commit.returncode != 0:
            return None, None
        # Result files written by earlier benchmarks of the same run are not a change of the code.
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no", "--", ".",
                                ":(exclude)bench/results"], cwd=root, capture_output=True, text=True, timeout=10)
        return commit.stdout.strip(), bool(dirty.stdout.strip())
    except (OSError, subprocess.SubprocessError):
        return None, None


def environment(device) -> dict:
    """What a result file records about where it was measured.

    Returns:
        ``device``, ``device_name``, ``date`` (UTC, ISO 8601), ``versions`` (Python, platform,
        warp_ccd, Warp, numpy and the optional peers' packages, None when missing),
        ``git_commit`` and ``git_dirty``.
    """
    versions = {"python": platform.python_version(), "platform": platform.platform(), "warp_ccd": None,
                "warp": wp.__version__, "numpy": np.__version__}
    for key, dist in (("warp_ccd", "warp-ccd"), ("python-fcl", "python-fcl"), ("newton", "newton"),
                      ("matplotlib", "matplotlib")):
        try:
            versions[key] = importlib.metadata.version(dist)
        except importlib.metadata.PackageNotFoundError:
            versions[key] = None
    commit, dirty = git_commit()
    return {
        "device": str(device),
        "device_name": getattr(device, "name", None),
        "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        "versions": versions,
        "git_commit": commit,
        "git_dirty": dirty,
    }


def write_json(path: str, document: dict) -> None:
    """Writes ``document`` to ``path``, replaced in one step (see :mod:`warp_ccd._src.output`).

    Raises:
        ValueError: ``path`` is not a writable ``.json`` destination.
    """
    prepare_text(path, json.dumps(document, indent=1) + "\n", JSON_EXTENSIONS, "JSON").commit()


class BenchReport:
    """Collects cases; prints tables; writes JSON and the plot.

    Args:
        device: Warp device.
        config: options to record (JSON-ready).
        reference: the method ratios are taken against.
    """

    def __init__(self, device, config: dict, reference: str = REFERENCE):
        self.device = device
        self.config = config
        self.reference = reference
        self.cases: list[CaseResult] = []
        self.environment = environment(device)

    def add(self, case: CaseResult) -> None:
        """Adds a measured case."""
        self.cases.append(case)

    @property
    def ok(self) -> bool:
        """No real mismatch in any case."""
        return all(c.ok for c in self.cases)

    def rows(self) -> list[dict]:
        """One dict per ``(method, N, triangles, stage)``."""
        out = []
        for c in self.cases:
            for method, st in c.times.items():
                obj, tri = c.counts.get(method, (None, None))
                for stage, (lo, med) in st.summary().items():
                    out.append({
                        "method": method, "n_objects": c.num_objects, "triangles": c.label,
                        "triangles_per_object": round(c.num_triangles / max(c.num_objects, 1), 3),
                        "stage": stage, "ms_min": lo, "ms_median": med,
                        "object_pairs": obj, "triangle_pairs": tri, "frames": st.frames(stage),
                        "mode": st.best_mode.get(stage), "peer_wrong": method in c.wrong_peers,
                    })
        return out

    def to_json(self) -> dict:
        """The JSON document."""
        return {
            **self.environment,
            "config": self.config,
            "rows": self.rows(),
            "memory": [{"method": self.reference, "n_objects": c.num_objects, "triangles": c.label,
                        "num_triangles": c.num_triangles, **c.memory} for c in self.cases if c.memory],
            "checks": [{"n_objects": c.num_objects, "triangles": c.label, **k.to_dict()}
                       for c in self.cases for k in c.checks],
            "notes": [{"n_objects": c.num_objects, "triangles": c.label, "note": note}
                      for c in self.cases for note in c.notes],
            "ok": self.ok,
        }

    def write_json(self, path: str) -> None:
        """Writes :meth:`to_json` to ``path``."""
        write_json(path, self.to_json())

    def case_table(self, c: CaseResult) -> str:
        """The table of one case, its memory, checks and verdict."""
        ref = c.times.get(self.reference)
        ref_med = {s: m for s, (_, m) in ref.summary().items()} if ref else {}
        lines = [
            f"== {c.num_objects:,} objects, triangles {c.label} ({c.num_triangles / max(c.num_objects, 1):.1f} per "
            f"object, {c.num_triangles:,} in all) on {self.device}, {self.config['frames']} frames after "
            f"{self.config['warmup']} warm-up",
            f"{'method':<14}{'stage':<15}{'ms min':>10}{'ms median':>11}{'/' + self.reference:>14}"
            f"{'object pairs':>14}{'tri pairs':>11}",
        ]
        for method, st in c.times.items():
            obj, tri = c.counts.get(method, (None, None))
            summary = st.summary()
            name = method + ("*" if method in c.wrong_peers else "")
            for k, (stage, (lo, med)) in enumerate(summary.items()):
                ratio = ""
                if method != self.reference and stage in ref_med and ref_med[stage] > 0:
                    ratio = f"{med / ref_med[stage]:.2f}x"
                if stage in st.best_mode:
                    stage = f"{stage} ({st.best_mode[stage]})"
                last = k == len(summary) - 1
                obj_text = obj if last and obj is not None else ""
                tri_text = tri if last and tri is not None else ""
                lines.append(f"{name if k == 0 else '':<14}{stage:<15}{lo:>10.3f}{med:>11.3f}{ratio:>14}"
                             f"{obj_text:>14}{tri_text:>11}")
        if c.memory:
            m = c.memory
            pool = f", CUDA pool high-water {_bytes(m['mempool_peak_bytes'])}" if m.get("mempool_peak_bytes") else ""
            lines.append(f"memory: {self.reference} pipeline peak {_bytes(m['pipeline_peak_bytes'])} "
                         f"({m['pipeline_peak_bytes_per_triangle']:.1f} B/triangle, {m['peak_source']}{pool}), "
                         f"resident {_bytes(m['pipeline_resident_bytes'])}; scene {_bytes(m['scene_bytes'])} "
                         f"({m['scene_bytes_per_triangle']:.1f} B/triangle)")
        lines += [f"note: {n}" for n in c.notes]
        lines += [f"check: {k.summary()}" for k in c.checks]
        for k in c.checks:
            lines += [f"  MISMATCH: {m}" for m in k.mismatches]
            lines += [f"  PEER WRONG: {m}" for m in k.peer_errors]
        if c.wrong_peers:
            lines.append(f"* {', '.join(sorted(c.wrong_peers))}: wrong answers in this case (a finding about the "
                         f"peer, judged by an independent check; {self.reference} stands)")
        agreeing = ", ".join(k.peer for k in c.checks if k.ok and k.peer_ok)
        verdict = "OK" if c.ok else "MISMATCH"
        lines.append(f"VERDICT {c.num_objects:,} objects, triangles {c.label}: {verdict}"
                     + (f" ({agreeing} agree with {self.reference})" if c.ok and agreeing else "")
                     + ("" if c.checks else " (no peer to compare with)"))
        return "\n".join(lines)

    def summary_table(self, stage: str = "total") -> str:
        """Medians of ``stage`` per N and method, with each peer's ratio to the reference."""
        methods = []
        for c in self.cases:
            for m, st in c.times.items():
                if st.has(stage) and m not in methods:
                    methods.append(m)
        broad = [m for c in self.cases for m, st in c.times.items() if not st.has("detect") and st.has("broad")]
        broad = list(dict.fromkeys(([self.reference] if broad else []) + broad))
        width = 22
        head = f"{'triangles':<10}{'objects':>10}" + "".join(f"{m:>{width}}" for m in methods)
        if broad:
            head += "   | broad:" + "".join(f"{m:>{width}}" for m in broad)
        lines = [f"ms per frame, median ({stage} = motion + detection; in brackets: peer / {self.reference}), "
                 f"{self.device}",
                 head]

        def cell(c, m, s):
            st = c.times.get(m)
            if st is None or not st.has(s):
                return f"{'-':>{width}}"
            med = st.summary()[s][1]
            ref = c.times.get(self.reference)
            text = f"{med:.3f}"
            if m != self.reference and ref is not None and ref.has(s) and ref.summary()[s][1] > 0:
                text += f" ({med / ref.summary()[s][1]:.2f}x)"
            if m in c.wrong_peers:
                text += "*"
            return f"{text:>{width}}"

        for c in self.cases:
            line = f"{c.label:<10}{c.num_objects:>10,}" + "".join(cell(c, m, stage) for m in methods)
            if broad:
                line += "   |       " + "".join(cell(c, m, "broad") for m in broad)
            lines.append(line)
        if any(c.wrong_peers for c in self.cases):
            lines.append("* the peer's answers were wrong in that case (see its check lines)")
        return "\n".join(lines)

    def plot(self, path: str) -> str | None:
        """Log-log ms per frame (median ``total``; broad phases dashed) against N; returns a note
        when matplotlib is missing (then nothing is written)."""
        try:
            from matplotlib.figure import Figure
        except ImportError as exc:
            return f"plot skipped: matplotlib is not installed ({exc})"
        fig = Figure(figsize=(8, 5.5), dpi=120)
        ax = fig.subplots()
        methods = list(dict.fromkeys(m for c in self.cases for m in c.times))
        labels = list(dict.fromkeys(c.label for c in self.cases))
        colours = {m: f"C{k % 10}" for k, m in enumerate(methods)}
        markers = {t: "osD^vP*X"[k % 8] for k, t in enumerate(labels)}
        series = {}
        for c in self.cases:
            for m, st in c.times.items():
                summary = st.summary()
                # Whole frames solid; broad phases dashed (this package's too, beside newton's).
                for stage, style in (("total", "-"), ("broad", "--")):
                    if stage not in summary or (stage == "broad" and m != self.reference and "total" in summary):
                        continue
                    key = (m, stage, c.label, style, stage in st.best_mode)
                    series.setdefault(key, []).append((c.num_objects, summary[stage][1]))
        for (m, stage, label, style, best_of), pts in series.items():
            pts.sort()
            what = ("frame" if stage == "total" else "broad phase") + (", best of eager/graph" if best_of else "")
            ax.plot([p[0] for p in pts], [p[1] for p in pts], style, color=colours[m], marker=markers[label],
                    markersize=4, label=f"{m} ({what}), triangles {label}")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("objects N")
        ax.set_ylabel("ms per frame (median)")
        device_name = getattr(self.device, "name", self.device)
        ax.set_title(f"warp_ccd scaling on {device_name} ({self.environment['date'][:10]})")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
        fig.tight_layout()
        full, _ = check_output_path(path, PLOT_EXTENSIONS, "plot")
        pending = PendingFile(full)
        fig.savefig(pending.temp_path)
        pending.commit()
        return None
