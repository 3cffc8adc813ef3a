"""Per-pixel error against time: Cycles' spp ladder and lpmbake's settings on one plot.

    python3 scripts/bench/cycles_plot.py OUT.png REPORT.json [REPORT.json ...]

Reads the report.json files of scripts/bench/cycles_side_by_side.sh (runs against the same
Cycles renders, e.g. one of the option sets and one with --cycles-from of the presets) and
draws, for the per-pixel and the 4x4-block relative L1: Cycles' ladder (error against
render seconds), the reference's own noise, and each lpmbake setting (bake + render
seconds) as a star. docs/accuracy.md, "Presets", and docs/cycles_comparison.md use it.
"""
import json
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def main():
    out, reports = sys.argv[1], [json.load(open(p)) for p in sys.argv[2:]]
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    for ax, key, title in ((axes[0], "err_px", "per pixel"), (axes[1], "err_blk", "over 4x4 blocks")):
        ladder = sorted({(r["spp"], r["seconds"], r[key]) for rep in reports for r in rep["rows"]
                         if r["kind"] == "ladder"})
        ax.plot([t for _, t, _ in ladder], [e for _, _, e in ladder], "o-", color="tab:blue", label="Cycles ladder")
        for spp, t, e in ladder:
            ax.annotate("%d spp" % spp, (t, e), textcoords="offset points", xytext=(5, 3), fontsize=8)
        seen = set()
        for rep in reports:
            for r in rep["rows"]:
                if r["kind"] != "lpmbake" or r["setting"] in seen:
                    continue
                seen.add(r["setting"])
                ax.plot(r["seconds"], r[key], "*", ms=13, color="tab:red")
                ax.annotate(r["setting"], (r["seconds"], r[key]), textcoords="offset points", xytext=(6, -10),
                            fontsize=8, color="tab:red")
        ref = [r for rep in reports for r in rep["rows"] if r["kind"] == "reference"][0]
        noise = reports[0].get("noise") or [{}]
        n = noise[0].get("pixel" if key == "err_px" else "blocks")
        if isinstance(n, (int, float)):
            ax.axhline(n, color="grey", ls=":", lw=1, label="reference's own noise (%d spp)" % ref["spp"])
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("seconds on 2 cores (Cycles: render; lpmbake: bake + render)")
        ax.set_ylabel("relative L1 against the Cycles reference")
        ax.set_title("%s (192x192, 1M-voxel plume)" % title, fontsize=10)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out, dpi=80)
    print("cycles_plot: wrote", out)


if __name__ == "__main__":
    main()
