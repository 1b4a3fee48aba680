"""An exported (or `fly --mcap`) MCAP file against its run's log.csv, read with the `mcap`
reader and `mcap-protobuf-support` (docs/live-view.md): its channels, the /tf world → drone
transforms, and the /pose attitude — roll and pitch taken back out of each quaternion
(intrinsic Z-Y-X) and compared with navdata's nav_roll_deg / nav_pitch_deg.

    ardrone-nmpc simulate configs/square.yaml --log-dir /tmp/runs
    ardrone-nmpc export /tmp/runs/<run> --format mcap -o /tmp/square.mcap
    python benchmarks/mcap_attitude_check.py /tmp/runs/<run> /tmp/square.mcap
"""

from __future__ import annotations

import sys

import numpy as np
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

from ardrone_nmpc.runs.rundir import read_run


def main(run_dir: str, path: str) -> None:
    run = read_run(run_dir)
    topics, tf, poses = {}, [], []
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        for c in summary.channels.values():
            topics[c.topic] = (summary.schemas[c.schema_id].name, c.message_encoding)
        for _, channel, _, msg in reader.iter_decoded_messages(topics=["/tf", "/pose"]):
            (tf if channel.topic == "/tf" else poses).append(msg)
    print("channels:", ", ".join(f"{t} {n} ({e})" for t, (n, e) in sorted(topics.items())))
    drone = [m for m in tf if m.child_frame_id == "drone"]
    print(f"/tf: {len(tf)} FrameTransform messages, {len(drone)} world → drone")
    q = np.array([[p.pose.orientation.x, p.pose.orientation.y, p.pose.orientation.z,
                   p.pose.orientation.w] for p in poses])
    has_pose = np.isfinite(run.columns["x_m"])
    roll, pitch = run.columns["nav_roll_deg"][has_pose], run.columns["nav_pitch_deg"][has_pose]
    tilted = np.hypot(roll, pitch) > 1.0
    qxy = np.abs(q[:, 0]) + np.abs(q[:, 1])
    print(f"/pose: {len(poses)} messages for {int(has_pose.sum())} rows with a position; "
          f"{int(tilted.sum())} rows tilt > 1°, of which {int((qxy[tilted] > 1e-3).sum())} have "
          f"|qx| + |qy| > 1e-3; max |qx| {np.abs(q[:, 0]).max():.4f}, max |qy| "
          f"{np.abs(q[:, 1]).max():.4f}")
    x, y, z, w = q.T
    roll_q = np.degrees(np.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y)))
    pitch_q = -np.degrees(np.arcsin(np.clip(2 * (w * y - z * x), -1, 1)))  # θ = −nav pitch
    ok = np.isfinite(roll)
    print(f"against log.csv: max |roll(q) − nav_roll_deg| {np.abs(roll_q - roll)[ok].max():.2e}°,"
          f" max |pitch(q) − nav_pitch_deg| {np.abs(pitch_q - pitch)[ok].max():.2e}°")


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
