#!/usr/bin/env python3
"""Runs `toolbench perceive` over a range of seeds and summarises recognition, pose, Table 5.3 score and
wall time per tool (quote it as measured under whatever load the machine had).

Usage: scripts/perceive_sweep.py BINARY OUT_DIR [--first 1] [--count 20] [perceive options...]
Writes OUT_DIR/seed<N>/ per seed and OUT_DIR/summary.json; prints the summary.
A tool counts as a correct pose when it is recognised as the right model, its handle centre is
within 2 cm and its handle axis within 15 deg of the truth, and its effector direction (x_T)
within 90 deg (effector facing the right way).
"""
import argparse
import json
import statistics
import subprocess
import sys
from pathlib import Path


def percentile(values, p):
    if not values:
        return None
    v = sorted(values)
    rank = p / 100 * (len(v) - 1)
    lo = int(rank)
    hi = min(lo + 1, len(v) - 1)
    return v[lo] + (v[hi] - v[lo]) * (rank - lo)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("binary")
    ap.add_argument("out")
    ap.add_argument("--first", type=int, default=1)
    ap.add_argument("--count", type=int, default=20)
    a, extra = ap.parse_known_args()  # anything else goes to `perceive`
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    tools = []
    per_tool_ms = []
    stage_ms = {k: [] for k in ("segmentation", "cloud", "classification", "recognition", "shape")}
    for seed in range(a.first, a.first + a.count):
        d = out / f"seed{seed}"
        subprocess.run([a.binary, "--log-level", "warn", "perceive", "--seed", str(seed), "--out", str(d)] + extra,
                       check=True, stdout=subprocess.DEVNULL)
        analysis = json.loads((d / "analysis.json").read_text())
        score = json.loads((d / "score.json").read_text())
        for t in analysis["tools"]:
            for k in stage_ms:
                stage_ms[k].append(t["ms"][k])
            per_tool_ms.append(t["ms"]["total"])
        for t in score["tools"]:
            t["seed"] = seed
            tools.append(t)
    correct = [t for t in tools if t.get("recognition_correct")]
    handle = [t["handle_error_m"] for t in correct]
    pose_ok = [t for t in correct if t["handle_error_m"] <= 0.02 and t["axis_error_deg"] <= 15 and
               t.get("effector_error_deg", 0) <= 90]
    summary = {
        "seeds": [a.first, a.first + a.count - 1],
        "tools": len(tools),
        "missed": sum(1 for t in tools if t.get("missed")),
        "recognition_correct": len(correct),
        "pose_correct": len(pose_ok),
        "handle_error_m_median_correct": percentile(handle, 50),
        "handle_error_m_p90_correct": percentile(handle, 90),
        "handle_error_m_median_all": percentile([t["handle_error_m"] for t in tools if "handle_error_m" in t], 50),
        "handle_error_m_p90_all": percentile([t["handle_error_m"] for t in tools if "handle_error_m" in t], 90),
        "ms_per_tool_median": percentile(per_tool_ms, 50),
        "ms_per_tool_p90": percentile(per_tool_ms, 90),
        "ms_stage_median": {k: percentile(v, 50) for k, v in stage_ms.items()},
        "mean_score": statistics.fmean([t["score"] for t in tools]) if tools else None,
        "wrong": [f"seed{t['seed']} {t['name']} {t['cell']} -> {t.get('recognised_as')}"
                  for t in tools if not t.get("recognition_correct")],
        "bad_pose": [f"seed{t['seed']} {t['name']} {t['cell']} handle {t['handle_error_m']*1000:.1f} mm axis "
                     f"{t['axis_error_deg']:.1f} deg effector {t.get('effector_error_deg', float('nan')):.0f} deg"
                     for t in correct if t not in pose_ok],
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    print(json.dumps(summary, indent=2))


if __name__ == "__main__":
    sys.exit(main())
