"""Markdown tables and gnuplot figures for guided_matching.py. Standard library only."""

import shutil
import subprocess
from pathlib import Path

from gm_runs import log


def fmt(value, digits=1, percent=False):
    if value is None:
        return "–"
    if percent:
        return f"{100.0 * value:.{digits}f} %"
    if isinstance(value, int):
        return str(value)
    return f"{value:.{digits}f}"


SLOW = 1.3  # a run whose median matching time per pair is this much above the truth run's


def timed(row, key, digits=1):
    """A time with a dagger when the run was slowed by other jobs (see README)."""
    value = row.get(f"{key}_s")
    slowdown = row.get(f"{key}_slowdown")
    mark = " †" if slowdown is not None and slowdown > SLOW else ""
    return fmt(value, digits) + mark


def components_text(row):
    """'exhaustive / vocabtree' frames in the largest connected component of verified pairs."""
    c = row.get("components") or {}
    return f"{fmt(c.get('exhaustive'))} / {fmt(c.get('vocab'))}"


COMPONENTS_HEADER = "largest component, exhaustive / vocab"


def markdown_table(header, rows):
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)


def sweep_table(rows):
    header = ["set", "variant", "frames", "repeats", "stride", "span", "density",
              "exhaustive s", "lowres s", "vocabtree s", "optimum s", "vocab / optimum",
              "exhaustive / vocab", "lowres / vocab", "vocab pair recall",
              "vocab inlier-weighted recall", COMPONENTS_HEADER]
    body = []
    for r in rows:
        ex = timed(r, "exhaustive") + ("" if r["exhaustive_measured"] else " (est.)")
        body.append([r["set"], r["variant"], r["frames"], r["repeats"], r["stride"], r["span"],
                     fmt(r["density"], 1, True), ex, timed(r, "lowres"), timed(r, "vocab"),
                     fmt(r["optimum_s"]), fmt(r["vocab_over_optimum"], 2),
                     fmt(r["exhaustive_over_vocab"], 1), fmt(r["lowres_over_vocab"], 2),
                     fmt(r["vocab"]["pair_recall"], 1, True),
                     fmt(r["vocab"]["weighted_recall"], 2, True), components_text(r)])
    return markdown_table(header, body)


def breakdown_table(rows):
    header = ["set", "variant", "frames", "vocabtree s", "tree build s", "scoring s",
              "proposal s", "matching s", "of which sequential s", "other s", "rounds",
              "pairs sequential",
              "pairs by score", "pairs by growing", "verified in rounds",
              "pairs matched / exhaustive verified"]
    body = []
    for r in rows:
        b = r["breakdown"]
        body.append([r["set"], r["variant"], r["frames"], timed(r, "vocab"),
                     fmt(b["build_s"]), fmt(b["score_s"]), fmt(b["propose_s"], 2),
                     fmt(b["match_s"]), fmt(b["match_sequential_s"]), fmt(b["other_s"], 2),
                     b["rounds"], b["pairs_sequential"],
                     b["pairs_by_score"], b["pairs_by_growing"], b["verified_in_rounds"],
                     fmt(b["matched_over_truth"], 2)])
    return markdown_table(header, body)


def recall_table(rows, target_frames):
    header = ["set", "frames", "exhaustive verified", "density", "pairs > overlap apart",
              "loop pairs", "vocab verified", "pair recall", "recall of pairs > overlap apart",
              "loop pairs found", "inlier-weighted recall", "inlier matches recovered",
              "lowres pair recall", "lowres inlier-weighted", "exhaustive s", "lowres s",
              "vocabtree s", "optimum s", "vocab / optimum", "measured optimum s",
              "vocab / measured optimum", "targets", COMPONENTS_HEADER,
              "lowres largest component"]
    body = []
    for r in rows:
        v, lo = r["vocab"], r["lowres"]
        body.append([r["set"], r["frames"], v["pairs_truth"], fmt(r["density"], 1, True),
                     v["far_pairs"], v["loop_pairs"], v["pairs_found"],
                     fmt(v["pair_recall"], 1, True), fmt(v["far_recall"], 1, True),
                     v["loop_found"], fmt(v["weighted_recall"], 2, True),
                     fmt(v["inlier_recall"], 2, True), fmt(lo["pair_recall"], 1, True),
                     fmt(lo["weighted_recall"], 2, True), timed(r, "exhaustive"),
                     timed(r, "lowres"), timed(r, "vocab"), fmt(r["optimum_s"]),
                     fmt(r["vocab_over_optimum"], 2), fmt(r["optimum_measured_s"]),
                     fmt(r["vocab_over_measured_optimum"], 2), targets_text(r, target_frames),
                     components_text(r), fmt(r["components"]["lowres"])])
    return markdown_table(header, body)


def targets_text(row, target_frames):
    if row["frames"] < target_frames:
        return f"n/a (< {target_frames} frames)"
    recall_ok = row["vocab"]["weighted_recall"] is not None and row["vocab"]["weighted_recall"] >= 0.98
    time_ok = row["vocab_over_optimum"] is not None and row["vocab_over_optimum"] <= 1.25
    return (f"recall {'meets' if recall_ok else 'MISSES'} (≥ 98 %), "
            f"time {'meets' if time_ok else 'MISSES'} (≤ 1.25 × optimum)")


def settings_table(rows):
    header = ["set", "frames", "vocabtree flags", "vocabtree s", "optimum s", "vocab / optimum",
              "vocab / measured optimum",
              "tree build s", "scoring s", "rounds", "pairs matched", "pair recall",
              "recall of pairs > overlap apart", "inlier-weighted recall", COMPONENTS_HEADER]
    body = []
    for r in rows:
        b, v = r["breakdown"], r["vocab"]
        body.append([r["set"], r["frames"], f"`{r['flags'] or '(defaults)'}`", timed(r, "vocab"),
                     fmt(r["optimum_s"]), fmt(r["vocab_over_optimum"], 2),
                     fmt(r["vocab_over_measured_optimum"], 2), fmt(b["build_s"]),
                     fmt(b["score_s"]), b["rounds"], b["pairs_matched"],
                     fmt(v["pair_recall"], 1, True), fmt(v["far_recall"], 1, True),
                     fmt(v["weighted_recall"], 2, True), components_text(r)])
    return markdown_table(header, body)


# ----------------------------------------------------------------------------------------------
# Figures (gnuplot)


def gnuplot_available():
    return shutil.which("gnuplot") is not None


def _run_gnuplot(script, path):
    script_path = path.with_suffix(".gp")
    script_path.write_text(script)
    done = subprocess.run(["gnuplot", str(script_path)], capture_output=True, text=True)
    if done.returncode != 0:
        log(f"warning: gnuplot failed on {script_path}: {done.stderr.strip()}")
    else:
        log(f"wrote {path}")


def _sweep_panels(rows, key, xlabel, data_dir, stem, logx=False):
    sets = sorted({r["set"] for r in rows}, key=lambda s: [r["set"] for r in rows].index(s))
    panels = []
    for name in sets:
        mine = sorted((r for r in rows if r["set"] == name), key=lambda r: r[key])
        dat = data_dir / f"{stem}_{name}.dat"
        lines = ["# x exhaustive lowres vocabtree optimum"]
        for r in mine:
            x = 100.0 * r[key] if key == "density" else r[key]
            lines.append(f"{x:.4f} {r['exhaustive_s']:.3f} {r['lowres_s']:.3f} "
                         f"{r['vocab_s']:.3f} {r['optimum_s']:.3f}")
        dat.write_text("\n".join(lines) + "\n")
        panels.append(
            f"set title '{name}'\nset xlabel '{xlabel}'\nset ylabel 'matching time (s)'\n"
            + ("set logscale x\n" if logx else "unset logscale x\n")
            + f"plot '{dat}' u 1:2 w lp pt 7 lw 2 t 'exhaustive', "
              f"'' u 1:3 w lp pt 5 lw 2 t 'lowres', '' u 1:4 w lp pt 9 lw 2 t 'vocabtree', "
              f"'' u 1:5 w l dt 2 lw 2 t 'optimum (exhaustive x density)'\n")
    return panels


def plot_sweep(rows, key, xlabel, out_dir, stem, title):
    if not rows:
        return
    data_dir = out_dir / "plot_data"
    data_dir.mkdir(parents=True, exist_ok=True)
    panels = _sweep_panels(rows, key, xlabel, data_dir, stem)
    path = out_dir / f"{stem}.png"
    width = 560 * len(panels)
    script = (f"set terminal pngcairo size {width},480 font 'sans,10' noenhanced\nset output '{path}'\n"
              f"set multiplot layout 1,{len(panels)} title '{title}'\n"
              "set logscale y\nset grid\nset key below\n" + "".join(panels) + "unset multiplot\n")
    _run_gnuplot(script, path)


def plot_breakdown(rows, out_dir):
    if not rows:
        return
    data_dir = out_dir / "plot_data"
    data_dir.mkdir(parents=True, exist_ok=True)
    dat = data_dir / "breakdown.dat"
    lines = ["# label build score propose match other"]
    for r in rows:
        b = r["breakdown"]
        label = f"{r['set']} {r['variant']}".replace(" ", "\\n", 1)
        lines.append(f"\"{label}\" {b['build_s']:.3f} {b['score_s']:.3f} {b['propose_s']:.3f} "
                     f"{b['match_sequential_s']:.3f} {b['match_s'] - b['match_sequential_s']:.3f} "
                     f"{max(0.0, b['other_s']):.3f}")
    dat.write_text("\n".join(lines) + "\n")
    path = out_dir / "breakdown.png"
    width = max(800, 70 * len(rows))
    script = (f"set terminal pngcairo size {width},520 font 'sans,9' noenhanced\nset output '{path}'\n"
              "set title 'vocabtree time breakdown'\nset ylabel 'seconds'\n"
              "set style data histograms\nset style histogram rowstacked\n"
              "set style fill solid 0.85 border -1\nset boxwidth 0.75\nset grid ytics\n"
              "set xtics rotate by -45 font 'sans,8'\nset key outside right top\nset bmargin 9\n"
              f"plot '{dat}' u 2:xtic(1) t 'tree build', '' u 3 t 'scoring', "
              "'' u 4 t 'pair proposal', '' u 5 t 'matching: sequential pairs', "
              "'' u 6 t 'matching: rounds', '' u 7 t 'other'\n")
    _run_gnuplot(script, path)


def plot_recall(rows, out_dir):
    if not rows:
        return
    data_dir = out_dir / "plot_data"
    data_dir.mkdir(parents=True, exist_ok=True)
    dat = data_dir / "recall.dat"
    lines = ["# set pair weighted far lowres_pair"]
    for r in rows:
        v = r["vocab"]
        far = v["far_recall"] if v["far_recall"] is not None else 1.0
        lines.append(f"\"{r['set']} ({r['frames']})\" {100 * v['pair_recall']:.3f} "
                     f"{100 * v['weighted_recall']:.3f} {100 * far:.3f} "
                     f"{100 * r['lowres']['pair_recall']:.3f}")
    dat.write_text("\n".join(lines) + "\n")
    path = out_dir / "recall.png"
    script = (f"set terminal pngcairo size 900,480 font 'sans,10' noenhanced\nset output '{path}'\n"
              "set title 'recall against exhaustive matching'\nset ylabel '%'\n"
              "set yrange [0:105]\nset style data histograms\nset style histogram clustered gap 1\n"
              "set style fill solid 0.85 border -1\nset grid ytics\nset key below\n"
              "set arrow from graph 0, first 98 to graph 1, first 98 nohead dt 2 lw 2\n"
              "set label 'target 98 %' at graph 0.01, first 99.5\n"
              f"plot '{dat}' u 2:xtic(1) t 'vocab pair recall', '' u 3 t 'vocab inlier-weighted', "
              "'' u 4 t 'vocab, pairs > overlap apart', '' u 5 t 'lowres pair recall'\n")
    _run_gnuplot(script, path)


def plot_components(rows, out_dir):
    """components.png: per set (whole sequence), frames in the largest connected component of
    the verified-pair graph (pairs with >= 15 inliers), vocabtree against exhaustive, as a
    percentage of the set's frames (bars) and in frames (labels)."""
    rows = [r for r in rows if r.get("components")]
    if not rows:
        return
    data_dir = out_dir / "plot_data"
    data_dir.mkdir(parents=True, exist_ok=True)
    dat = data_dir / "components.dat"
    lines = ["# set frames exhaustive vocabtree exhaustive_% vocabtree_%"]
    for r in rows:
        c = r["components"]
        lines.append(f"\"{r['set']} ({c['frames']} frames)\" {c['frames']} {c['exhaustive']} "
                     f"{c['vocab']} {100.0 * c['exhaustive'] / c['frames']:.2f} "
                     f"{100.0 * c['vocab'] / c['frames']:.2f}")
    dat.write_text("\n".join(lines) + "\n")
    path = out_dir / "components.png"
    width = max(700, 160 * len(rows))
    script = (f"set terminal pngcairo size {width},480 font 'sans,10' noenhanced\n"
              f"set output '{path}'\n"
              "set title 'largest connected component of verified pairs (>= 15 inliers): "
              "vocabtree against exhaustive'\n"
              "set ylabel '% of the frames (labels: frames)'\nset yrange [0:110]\n"
              "set style data histograms\nset style histogram clustered gap 1\n"
              "set style fill solid 0.85 border -1\nset grid ytics\nset key below\n"
              f"plot '{dat}' u 5:xtic(1) t 'exhaustive' lc rgb '#4477aa', "
              "'' u 6 t 'vocabtree' lc rgb '#ee6677', "
              # Frame counts over the bars: with two bars and gap 1 a bar is 1/3 wide, so the
              # bars of row i stand at i - 1/6 and i + 1/6.
              "'' u ($0 - 1.0/6):5:3 w labels offset 0,0.7 notitle, "
              "'' u ($0 + 1.0/6):6:4 w labels offset 0,0.7 notitle\n")
    _run_gnuplot(script, path)


def plot_all(results, out_dir):
    if not gnuplot_available():
        log("gnuplot not found: no figures (install it with `apt-get install gnuplot-nox`)")
        return
    plot_sweep(results["density_sweep"], "density", "density of the true match matrix (%)",
               out_dir, "density", "matching time against match-matrix density (fixed frames)")
    plot_sweep(results["frames_sweep"], "frames", "frames", out_dir, "frames",
               "matching time against frames (constant density)")
    plot_breakdown(results["breakdown"], out_dir)
    plot_recall(results["recall"], out_dir)
    plot_components(results["recall"], out_dir)
