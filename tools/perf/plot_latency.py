#!/usr/bin/env python3
"""Plots latency distributions of the daemon (tools/perf/pipeline_latency.sh
with HG_LATENCY_OUT) as cumulative curves, with the 50 ms p99 target.

  tools/perf/plot_latency.py OUT.png "LABEL=FILE" ["LABEL=FILE" ...]

Each FILE holds one latency in ms per line. Needs gnuplot.
"""

import os
import subprocess
import sys
import tempfile


def main():
    if len(sys.argv) < 3 or any("=" not in a for a in sys.argv[2:]):
        sys.exit(__doc__)
    out = sys.argv[1]
    curves = []
    with tempfile.TemporaryDirectory() as tmp:
        for i, arg in enumerate(sys.argv[2:]):
            label, path = arg.split("=", 1)
            with open(path) as f:
                values = sorted(float(line) for line in f if line.strip())
            if not values:
                sys.exit(f"{path}: no latencies")
            data = os.path.join(tmp, f"{i}.dat")
            with open(data, "w") as f:
                for k, v in enumerate(values):
                    f.write(f"{v} {100.0 * (k + 1) / len(values)}\n")
            p99 = values[min(len(values) - 1, int(0.99 * len(values)))]
            curves.append(f"'{data}' using 1:2 with lines lw 2 title "
                          f"'{label} (p99 {p99:.1f} ms, {len(values)} samples)'")
        script = f"""
set terminal pngcairo size 900,520 font 'sans,10'
set output '{out}'
set title 'Latency from capture stamp to the DDS sample received (cumulative)'
set xlabel 'latency (ms)'
set ylabel 'samples at or below (%)'
set grid
set key bottom right
set yrange [0:100]
set arrow from 50, graph 0 to 50, graph 1 nohead dt 2 lc rgb 'red'
set label 'p99 target 50 ms' at 51, graph 0.06 tc rgb 'red'
plot {', '.join(curves)}
"""
        subprocess.run(["gnuplot"], input=script, text=True, check=True)


if __name__ == "__main__":
    main()
