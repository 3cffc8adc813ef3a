"""Image helper for blender_import_test.sh, run with Blender's own Python (bpy reads and
writes EXR; no numpy, no OpenImageIO bindings needed):

  blender -b --factory-startup --python exr_tool.py -- white OUT.exr
      a constant lat-long environment of radiance 1 (16x8)
  blender -b --factory-startup --python exr_tool.py -- compare --ref REF.exr --test TEST.exr
      [--white REF_WHITE.exr [--white-radiance E]] [--min-coverage C] [--block B] [--max-mean M] [--max-p95 P]
      [--max-block X] [--max-alpha A] [--label NAME]

compare: REF is `lpmbake render` without an environment (background 0), REF_WHITE the same
render with the constant environment of 1 (which `lpmbake render` scales by the bake's
lpm:env_scale: pass that as E), so that 1 - (REF_WHITE - REF) / E is the volume's coverage
1 - T per pixel. The image is cut into BxB blocks; blocks whose mean coverage is at
least C "see the volume" (without --white: every block where REF is non-zero). For each such
block, relative L1 = sum |TEST - REF| / sum REF over its pixels and RGB. Prints one line:
blocks, mean / 95th percentile / max of the per-block relative L1, the whole selected area's
relative L1, and (when TEST has alpha, rendered with a transparent film) the largest block
mean of |alpha - coverage|. Exit 0 when mean <= M, 95th percentile <= P, max <= X and the
alpha difference <= A (each bound only when given), 1 otherwise, 2 on unreadable input.
"""

import argparse
import os
import sys

import bpy


def load(path):
    """(width, height, rows top to bottom of [r, g, b, a] per pixel)."""
    if not os.path.isfile(path):
        raise SystemExit("exr_tool: error: '%s' not found" % path)
    img = bpy.data.images.load(os.path.abspath(path))
    img.colorspace_settings.name = "Non-Color"     # the file's numbers, unconverted
    w, h = img.size
    if w == 0 or h == 0:
        raise SystemExit("exr_tool: error: cannot read '%s'" % path)
    px = list(img.pixels)   # RGBA, bottom row first
    rows = []
    for y in range(h - 1, -1, -1):
        base = y * w * 4
        rows.append([px[base + 4 * x: base + 4 * x + 4] for x in range(w)])
    has_alpha = img.depth in (32, 64, 128) and any(p[3] != 1.0 for r in rows for p in r)
    return w, h, rows, has_alpha


def write_white(path):
    img = bpy.data.images.new("white", 16, 8, float_buffer=True, alpha=False)
    img.pixels = [1.0] * (16 * 8 * 4)
    img.filepath_raw = os.path.abspath(path)
    img.file_format = "OPEN_EXR"
    img.save()


def compare(a):
    wr, hr, ref, _ = load(a.ref)
    wt, ht, test, test_alpha = load(a.test)
    if (wr, hr) != (wt, ht):
        print("exr_tool: error: %s is %dx%d, %s is %dx%d" % (a.ref, wr, hr, a.test, wt, ht))
        return 2
    cov = None
    if a.white:
        ww, hw, white, _ = load(a.white)
        if (ww, hw) != (wr, hr):
            print("exr_tool: error: %s has another size" % a.white)
            return 2
        k = 1.0 / (3.0 * a.white_radiance)
        cov = [[1.0 - k * sum(white[y][x][c] - ref[y][x][c] for c in range(3)) for x in range(wr)]
               for y in range(hr)]
    B = a.block
    rels, alpha_diffs = [], []
    num_all = den_all = 0.0
    for by in range(0, hr - B + 1, B):
        for bx in range(0, wr - B + 1, B):
            pix = [(y, x) for y in range(by, by + B) for x in range(bx, bx + B)]
            den = sum(ref[y][x][c] for y, x in pix for c in range(3))
            if cov is not None:
                if sum(cov[y][x] for y, x in pix) / len(pix) < a.min_coverage:
                    continue
            elif den <= 0:
                continue
            num = sum(abs(test[y][x][c] - ref[y][x][c]) for y, x in pix for c in range(3))
            rels.append(num / den if den > 0 else float("inf"))
            num_all += num
            den_all += den
            if cov is not None and test_alpha:
                alpha_diffs.append(sum(abs(test[y][x][3] - cov[y][x]) for y, x in pix) / len(pix))
    if not rels:
        print("%s: no block sees the volume" % a.label)
        return 1
    s = sorted(rels)
    mean = sum(rels) / len(rels)
    p95 = s[min(len(s) - 1, int(0.95 * len(s)))]
    line = "%s: %d blocks of %dx%d, relative L1 per block mean %.4f p95 %.4f max %.4f, area %.4f" % (
        a.label, len(rels), B, B, mean, p95, s[-1], num_all / den_all if den_all > 0 else float("inf"))
    amax = max(alpha_diffs) if alpha_diffs else None
    if amax is not None:
        line += ", alpha vs coverage max block %.4f" % amax
    ok = True
    fails = []
    if a.max_mean is not None and not mean <= a.max_mean:
        fails.append("mean %.4f > %.4f" % (mean, a.max_mean))
    if a.max_p95 is not None and not p95 <= a.max_p95:
        fails.append("p95 %.4f > %.4f" % (p95, a.max_p95))
    if a.max_block is not None and not s[-1] <= a.max_block:
        fails.append("max %.4f > %.4f" % (s[-1], a.max_block))
    if a.max_alpha is not None and (amax is None or not amax <= a.max_alpha):
        fails.append("alpha %s > %.4f" % ("missing" if amax is None else "%.4f" % amax, a.max_alpha))
    ok = not fails
    print(line + ("  [ok]" if ok else "  [FAIL: " + "; ".join(fails) + "]"), flush=True)
    return 0 if ok else 1


def main(argv):
    if argv and argv[0] == "white":
        write_white(argv[1])
        return 0
    p = argparse.ArgumentParser(prog="exr_tool compare")
    p.add_argument("cmd", choices=["compare"])
    p.add_argument("--ref", required=True)
    p.add_argument("--test", required=True)
    p.add_argument("--white")
    p.add_argument("--white-radiance", type=float, default=1.0,
                   help="the constant environment's radiance in REF_WHITE (1 x the bake's lpm:env_scale)")
    p.add_argument("--min-coverage", type=float, default=0.1)
    p.add_argument("--block", type=int, default=4)
    p.add_argument("--max-mean", type=float)
    p.add_argument("--max-p95", type=float)
    p.add_argument("--max-block", type=float)
    p.add_argument("--max-alpha", type=float)
    p.add_argument("--label", default="compare")
    return compare(p.parse_args(argv))


if __name__ == "__main__":
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    try:
        rc = main(argv)
    except SystemExit as e:
        print(e, file=sys.stderr)
        rc = 2
    sys.stdout.flush()
    os._exit(rc)
