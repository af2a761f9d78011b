#!/usr/bin/env python3
"""Turns Google Benchmark JSON from hg_bench into the generated part of
docs/performance.md (between the BEGIN/END markers; the rest of the file is kept)
and a gnuplot PNG of octree update times."""
import datetime
import json
import platform
import re
import subprocess
import sys
import tempfile

BEGIN = "<!-- BEGIN GENERATED (tools/perf/run_benchmarks.sh) -->"
END = "<!-- END GENERATED -->"


def cpu_model():
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def parse_args(name):
    # BM_OctreeIncremental/cams:8/depth:10/threads:2/iterations:15/process_time/real_time
    return {k: int(v) for k, v in re.findall(r"(\w+):(\d+)", name)}


def main(bench_json, doc_path, png_path):
    data = json.load(open(bench_json))
    ctx = data["context"]
    rows = [b for b in data["benchmarks"] if b.get("run_type", "iteration") == "iteration"]
    by_name = {b["name"].split("/")[0]: [] for b in rows}
    for b in rows:
        by_name[b["name"].split("/")[0]].append(b)

    def ms(b):
        t = b["real_time"]
        return {"ns": t / 1e6, "us": t / 1e3, "ms": t, "s": t * 1e3}[b["time_unit"]]

    lines = [BEGIN, ""]
    lines.append(
        f"Measured {datetime.date.today().isoformat()} on {cpu_model()}, "
        f"{ctx['num_cpus']} cores at {ctx['mhz_per_cpu']} MHz, "
        f"CMake Release build, command `tools/perf/run_benchmarks.sh`.")
    lines.append("")
    read = by_name.get("BM_ReadMask", [None])[0]
    build = by_name.get("BM_QuadtreeBuild1080p", [None])[0]
    if read and build:
        lines += ["### Silhouette steps, one 1920x1080 mask, one core", "",
                  "| step | time per mask | target |", "|---|---|---|",
                  f"| read the mask once (count pixels > T) | {ms(read):.3f} ms | reference |",
                  f"| quadtree build, changed flags included | {ms(build):.3f} ms | <= 0.5 ms |"]
        undistort = by_name.get("BM_UndistortApply1080p", [None])[0]
        if undistort:
            lines.append(f"| conservative undistortion (k1 = -0.12), only for distorting lenses "
                         f"| {ms(undistort):.3f} ms | none yet |")
        lines.append("")

    def octree_table(key, title, target):
        bench = by_name.get(key, [])
        if not bench:
            return []
        out = [f"### {title}", "",
               "| cameras | depth | threads | median ms | p99 ms | max ms | CPU ms / frame "
               "| nodes | target (median) |",
               "|---|---|---|---|---|---|---|---|---|"]
        for b in bench:
            a = parse_args(b["name"])
            cpu = b["cpu_time"] * {"ms": 1, "us": 1e-3, "ns": 1e-6, "s": 1e3}[b["time_unit"]]
            tgt = target if (a["cams"], a["depth"]) == (8, 10) and a["threads"] == 2 else ""
            out.append(f"| {a['cams']} | {a['depth']} | {a['threads']} | {b['median_ms']:.1f} | "
                       f"{b['p99_ms']:.1f} | {b['max_ms']:.1f} | {cpu:.1f} | "
                       f"{int(b['nodes']):,} | {tgt} |")
        return out + [""]

    lines += octree_table("BM_OctreeIncremental",
                          "Octree, incremental update (frame after frame at 30 Hz)", "<= 10 ms")
    lines += octree_table("BM_OctreeFromScratch", "Octree, from scratch", "<= 40 ms")
    dense_rows = sorted(by_name.get("BM_DenseCarve", []), key=lambda b: b["name"])
    if dense_rows:
        lines += ["### Dense per-voxel carve (baseline)", "",
                  "| grid | time per frame | dense / octree at the same resolution "
                  "| dense / octree at depth 10 (1024^3) |", "|---|---|---|---|"]
        inc = {(parse_args(b["name"])["depth"], parse_args(b["name"])["threads"]): b
               for b in by_name.get("BM_OctreeIncremental", []) if parse_args(b["name"])["cams"] == 8}
        for b in dense_rows:
            res = int(b["name"].split("/")[1])
            depth = res.bit_length() - 1
            same = (f"{ms(b) / inc[(depth, 2)]['median_ms']:.1f}x (depth {depth}, incremental, 2 threads)"
                    if (depth, 2) in inc else "")
            deep = (f"{ms(b) / inc[(10, 2)]['median_ms']:.2f}x (incremental, 2 threads)"
                    if (10, 2) in inc else "")
            lines.append(f"| {res}^3, 8 cameras, centre point per voxel, 1 thread | {ms(b):.1f} ms "
                         f"| {same} | {deep} |")
        lines.append("")
    lines += ["![octree update time per frame against depth](images/octree_times.png)", "", END]

    try:
        old = open(doc_path).read()
    except OSError:
        old = ""
    if BEGIN in old and END in old:
        new = old[:old.index(BEGIN)] + "\n".join(lines) + old[old.index(END) + len(END):]
    else:
        new = "# Performance\n\n" + "\n".join(lines) + "\n"
    open(doc_path, "w").write(new)

    # Plot: median time per frame against depth, 8 cameras, 2 threads.
    with tempfile.NamedTemporaryFile("w", suffix=".dat", delete=False) as dat:
        for key in ("BM_OctreeIncremental", "BM_OctreeFromScratch"):
            dat.write(f"# {key}\n")
            for b in sorted(by_name.get(key, []), key=lambda b: parse_args(b["name"])["depth"]):
                a = parse_args(b["name"])
                if a["cams"] == 8 and a["threads"] == 2:
                    dat.write(f"{a['depth']} {b['median_ms']}\n")
            dat.write("\n\n")
        dat_path = dat.name
    script = f"""
set terminal pngcairo size 900,560 font ',11'
set output '{png_path}'
set title 'hullguard octree update, 8 Full HD cameras, 3 walking people, 2 threads'
set xlabel 'octree depth (finest cells per axis = 2^{depth})'
set ylabel 'median time per frame (ms)'
set logscale y
set yrange [5:*]
set grid
set key left top
set xtics 7,1,10
plot '{dat_path}' index 0 with linespoints lw 2 pt 7 title 'incremental', \\
     '{dat_path}' index 1 with linespoints lw 2 pt 5 title 'from scratch', \\
     10 with lines dt 2 lc rgb 'dark-green' title 'target incremental (10 ms)', \\
     40 with lines dt 2 lc rgb 'red' title 'target from scratch (40 ms)'
"""
    subprocess.run(["gnuplot"], input=script, text=True, check=True)


if __name__ == "__main__":
    main(*sys.argv[1:4])
