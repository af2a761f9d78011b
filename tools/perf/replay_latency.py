#!/usr/bin/env python3
"""The daemon's own cost on camera frames: record, then replay from memory.

A config's simulated cameras render their frames on the same cores as the
daemon, which real cameras do not (their frames arrive by DMA). This script
records the config's cameras with `hullguard record` (a few cameras per run, so
that rendering and writing keep up with the rate), writes a copy of the config
whose cameras replay those recordings from memory in a loop
(`source: {type: replay, preload: true, loop: true}`, docs/cameras.md), and
runs tools/perf/pipeline_latency.sh on it: the latency and the rate of the
whole pipeline (background model, fusion, octree, DDS) without the renderer.

  tools/perf/replay_latency.py CONFIG [--record-s 8] [--loop-start-s 3.5]
      [--group 4] [--seconds 45] [--skip 20] [--work DIR [--reuse]] [--build build]

The recording keeps the empty cell that the background model learns from
(the sim's people appear after 2 * background.learn_frames frames plus 1 s)
out of the loop: each repetition starts at --loop-start-s. Preloading takes
width x height bytes per frame and camera (three times that for RGB): 8 Full
HD Bayer cameras, 8 s, about 4 GB. Prints pipeline_latency.sh's JSON, with
the recordings' frame counts. Needs python3-yaml.
"""

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile

import yaml


def absolute(path, base):
    return path if os.path.isabs(path) else os.path.normpath(os.path.join(base, path))


def main():
    root = os.path.normpath(os.path.join(os.path.dirname(os.path.abspath(__file__)), "../.."))
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("config")
    p.add_argument("--record-s", type=float, default=8.0)
    p.add_argument("--loop-start-s", type=float, default=3.5)
    p.add_argument("--group", type=int, default=4, help="cameras per recording run")
    p.add_argument("--seconds", type=int, default=45, help="daemon run")
    p.add_argument("--skip", type=int, default=20, help="start-up not measured (preload, learning)")
    p.add_argument("--work", help="folder for recordings and configs (default: a temporary one)")
    p.add_argument("--build", default=os.path.join(root, "build"))
    p.add_argument("--reuse", action="store_true",
                   help="replay the recordings already in --work instead of recording again")
    a = p.parse_args()

    config_path = os.path.abspath(a.config)
    base = os.path.dirname(config_path)
    with open(config_path) as f:
        config = yaml.safe_load(f)
    # Paths in the config are relative to its folder; the copies live elsewhere.
    for cam in config["cameras"]:
        src = cam["source"]
        if src.get("type") != "sim":
            sys.exit(f"{a.config}: camera {cam['name']} is not a sim camera")
        src["scene"] = absolute(src["scene"], base)
    for obstacle in config.get("obstacles", []):
        if "file" in obstacle:
            obstacle["file"] = absolute(obstacle["file"], base)

    work = a.work or tempfile.mkdtemp(prefix="hg_replay_latency_")
    os.makedirs(work, exist_ok=True)
    cameras = config["cameras"]
    groups = [cameras[i:i + a.group] for i in range(0, len(cameras), a.group)]
    frames = {}
    replay = dict(config, cameras=[])
    for g, group in enumerate(groups):
        rec = os.path.join(work, f"rec{g}")
        for cam in group:
            replay["cameras"].append(dict(cam, source={
                "type": "replay", "directory": rec, "camera": cam["name"], "preload": True,
                "loop": True, "loop_start_s": a.loop_start_s}))
        if a.reuse and os.path.exists(os.path.join(rec, "manifest.yaml")):
            frames.update({cam["name"]: "reused" for cam in group})
            continue
        shutil.rmtree(rec, ignore_errors=True)
        part = os.path.join(work, f"record{g}.yaml")
        with open(part, "w") as f:
            yaml.safe_dump(dict(config, cameras=group), f, sort_keys=False)
        out = subprocess.run(
            [os.path.join(a.build, "tools/hullguard"), "record", "--config", part, "--out", rec,
             "--seconds", str(a.record_s), "--format", "pnm", "--queue", "300", "--writers", "1"],
            capture_output=True, text=True)
        if out.returncode != 0:
            sys.exit(f"hullguard record failed ({out.returncode}):\n{out.stdout}{out.stderr}")
        for line in out.stdout.splitlines():
            if "frames kept" in line:
                name, rest = line.strip().split(":", 1)
                frames[name] = int(rest.split()[0])
    replay_path = os.path.join(work, "replay.yaml")
    with open(replay_path, "w") as f:
        yaml.safe_dump(replay, f, sort_keys=False)
    out = subprocess.run(
        [os.path.join(root, "tools/perf/pipeline_latency.sh"), replay_path, str(a.seconds),
         str(a.skip), a.build], capture_output=True, text=True)
    if out.returncode != 0:
        sys.exit(f"pipeline_latency.sh failed ({out.returncode}):\n{out.stdout}{out.stderr}")
    result = json.loads(out.stdout.strip().splitlines()[-1])
    result["config"] = os.path.relpath(config_path, root)
    result["recorded_frames"] = frames
    result["record_s"] = a.record_s
    result["loop_start_s"] = a.loop_start_s
    print(json.dumps(result))
    if not a.work:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
