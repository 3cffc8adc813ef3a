"""Plots and tables of the accuracy study (scripts/accuracy/run.sh).

    python3 scripts/accuracy/plot.py RESULTS.jsonl DOCS_DIR

Writes DOCS_DIR/accuracy/study_<scene>.png (band-0 voxel error and image error against
wall time, one curve per knob through the default, the presets marked, the Pareto front)
and replaces the text between "<!-- study:begin -->" and "<!-- study:end -->" in
DOCS_DIR/accuracy.md with the tables.
"""
import json
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

BEGIN, END = "<!-- study:begin -->", "<!-- study:end -->"


def load(path):
    rows = [json.loads(line) for line in open(path) if line.strip()]
    for r in rows:  # the bake's own time: the --verify check ran inside it and is reported apart
        r["seconds"] -= r["verify"]["seconds"]
    scenes = []
    for r in rows:
        if r["scene"] not in scenes:
            scenes.append(r["scene"])
    return rows, scenes


def pareto(rows, key):
    """The settings no other setting beats in both time and error."""
    front = []
    for r in rows:
        if not any(o["seconds"] <= r["seconds"] and o[key] < r[key] and o is not r for o in rows):
            front.append(r)
    return sorted(front, key=lambda r: r["seconds"])


def plot_scene(rows, scene, out_dir):
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    default = next((r for r in rows if r["setting"] == "default"), None)
    for ax in axes:
        ax.set_prop_cycle(color=plt.cm.tab20.colors)  # more knobs than the default 10 colours
    for ax, key, noise, title in ((axes[0], "band0_corrected", "band0_noise", "voxels: band-0 RMS error (MC noise removed)"),
                                  (axes[1], "block_l1", "block_l1_noise", "image: relative L1 over 4x4 blocks")):
        knobs = []
        for r in rows:
            if r["knob"] != "preset" and r["knob"] not in knobs:
                knobs.append(r["knob"])
        floor = 0.2 * rows[0][noise]  # errors below the reference's noise are drawn at 1/5 of it

        def y(r):
            return max(r[key], floor)

        for knob in knobs:
            pts = [r for r in rows if r["knob"] == knob] + ([default] if default else [])
            pts.sort(key=lambda r: r["seconds"])
            ax.plot([p["seconds"] for p in pts], [y(p) for p in pts], "o-", ms=4, lw=1, label=knob)
        for r in rows:
            if r["knob"] == "preset":
                ax.plot(r["seconds"], y(r), "*", ms=14, color="black")
                ax.annotate(r["setting"], (r["seconds"], y(r)), textcoords="offset points", xytext=(6, 4))
        front = pareto(rows, key)
        ax.plot([p["seconds"] for p in front], [y(p) for p in front], "--", color="grey", lw=2, label="Pareto front")
        ax.axhline(rows[0][noise], color="red", lw=0.8, ls=":", label="reference noise")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("bake wall time, s (2 threads)")
        ax.set_title(title, fontsize=10)
        ax.set_ylabel("error (below the noise: drawn at 1/5 of it)", fontsize=8)
        ax.grid(True, which="both", alpha=0.3)
    axes[1].legend(fontsize=7, loc="upper right")
    fig.suptitle("%s (%d active voxels)" % (scene, rows[0]["voxels"]))
    fig.tight_layout()
    os.makedirs(os.path.join(out_dir, "accuracy"), exist_ok=True)
    name = "accuracy/study_%s.png" % scene
    fig.savefig(os.path.join(out_dir, name), dpi=80)
    plt.close(fig)
    return name


def pct(x):
    return "%.2f%%" % (100 * x)


def scene_table(rows):
    front0 = {id(r) for r in pareto(rows, "band0_corrected")}
    lines = ["| setting | bake s | peak MiB | band-0 (noise) | bands 1-2 (noise) | image px L1 (noise) | 4x4 blocks (noise) "
             "| --verify 64 [95%], its time | front |", "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        b12 = "%s (%s)" % (pct(r["band12_rms"]), pct(r["band12_noise"])) if "band12_rms" in r else "-"
        v = r["verify"]
        lines.append("| %s | %.2f | %.0f | %s (%s) | %s | %s (%s) | %s (%s) | %s | %s |" % (
            r["setting"], r["seconds"], r["peak_rss_mib"], pct(r["band0_corrected"]), pct(r["band0_noise"]), b12,
            pct(r["image_l1"]), pct(r["image_l1_noise"]), pct(r["block_l1"]), pct(r["block_l1_noise"]),
            "%s [%s, %s] %.1f s" % (pct(v["error"]), pct(v["low"]), pct(v["high"]), v["seconds"]),
            "yes" if id(r) in front0 else ""))
    return lines


def presets_table(rows, scenes):
    lines = ["| scene | active voxels | preset | s | band-0 error | 4x4-block image error | --verify estimate |",
             "|---|---|---|---|---|---|---|"]
    for scene in scenes:
        for r in rows:
            if r["scene"] == scene and r["knob"] == "preset":
                lines.append("| %s | %d | %s | %.2f | %s | %s | %s |" % (
                    scene, r["voxels"], r["setting"], r["seconds"], pct(r["band0_corrected"]), pct(r["block_l1"]),
                    pct(r["verify"]["error"])))
    return lines


def agreement_table(path):
    """--verify 64 (the default bake) against 1024 probes of other voxels and paths."""
    if not os.path.exists(path) or os.path.getsize(path) == 0:
        return []
    lines = ["", "### --verify against a 16x larger check", "",
             "The default bake's `--verify 64` estimate and interval against the same error measured with "
             "1024 probes of other voxels and paths (`--verify 1024 --verify-seed 2`):", "",
             "| scene | 64 probes: estimate [95%] | 1024 probes: estimate [95%] | inside the 64-probe interval |",
             "|---|---|---|---|"]
    for line in open(path):
        a = json.loads(line)
        s, b = a["probes64"], a["probes1024"]
        inside = s["low"] <= b["error"] <= s["high"]
        lines.append("| %s | %s [%s, %s] | %s [%s, %s] | %s |" % (
            a["scene"], pct(s["error"]), pct(s["low"]), pct(s["high"]), pct(b["error"]), pct(b["low"]),
            pct(b["high"]), "yes" if inside else "no"))
    return lines


def main():
    rows, scenes = load(sys.argv[1])
    docs = sys.argv[2]
    text = ["Generated by `bash scripts/accuracy/run.sh` (do not edit by hand).", "", "### Presets", ""]
    text += presets_table(rows, scenes)
    text += agreement_table(os.path.join(os.path.dirname(sys.argv[1]), "verify.jsonl"))
    for scene in scenes:
        sub = [r for r in rows if r["scene"] == scene]
        png = plot_scene(sub, scene, docs)
        text += ["", "### %s" % scene, "", "![%s](%s)" % (scene, png), "",
                 "The default bake: Monte Carlo reference | `lpmbake render` | difference x 4 "
                 "(accuracy/%s_images.png):" % scene, "", "![%s images](accuracy/%s_images.png)" % (scene, scene), ""]
        text += scene_table(sub)
    path = os.path.join(docs, "accuracy.md")
    doc = open(path).read()
    if BEGIN not in doc:
        doc += "\n## The study\n\n%s\n%s\n" % (BEGIN, END)
    head, rest = doc.split(BEGIN, 1)
    tail = rest.split(END, 1)[1]
    open(path, "w").write(head + BEGIN + "\n" + "\n".join(text) + "\n" + END + tail)
    print("plot.py: %d rows, %d scenes -> %s" % (len(rows), len(scenes), path))


if __name__ == "__main__":
    main()
