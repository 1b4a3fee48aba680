"""The child process of :class:`~ardrone_nmpc.links.motioncapture_source.MotionCaptureSource`:
runs libmotioncapture and writes its frames to stdout, one JSON line each.

A process of its own because the library's ``connect`` keeps Python's GIL while it waits
(Vicon's retries until a server answers, OptiTrack's waits for a reply): in the tool's process
that would freeze every thread, and Ctrl-C with them. Run as a script (``python FILE SYSTEM
OPTIONS_JSON``); it imports nothing of the package.

Lines: ``{"connected": true}`` or ``{"error": "…"}`` first, then per frame
``{"b": [[name, x, y, z, qw, qx, qy, qz], …]}`` (metres, the library's float32 values as
doubles) or ``{"frame_error": "…"}``. It ends when stdout is closed, or with its parent.
"""

import json
import sys
import time


def _die_with_parent() -> None:
    try:  # Linux: SIGKILL when the parent dies, even while connect() blocks
        import ctypes
        import signal

        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass


def _write(out, record) -> None:
    out.write(json.dumps(record) + "\n")
    out.flush()


def main(argv) -> int:
    _die_with_parent()
    out = sys.stdout
    system, options = argv[1], json.loads(argv[2])
    try:
        import motioncapture
    except ImportError as exc:
        _write(out, {"error": f"cannot import motioncapture: {exc}"})
        return 3
    try:
        mc = motioncapture.connect(system, options)
    except Exception as exc:  # noqa: BLE001 - the library raises RuntimeError and others
        _write(out, {"error": str(exc) or type(exc).__name__})
        return 2
    _write(out, {"connected": True})
    while True:
        try:
            mc.waitForNextFrame()
            bodies = []
            for name, body in mc.rigidBodies.items():
                q = body.rotation
                bodies.append([name, *(float(v) for v in body.position),
                               float(q.w), float(q.x), float(q.y), float(q.z)])
            record = {"b": bodies}
        except Exception as exc:  # noqa: BLE001 - reported; the parent counts it
            record = {"frame_error": str(exc) or type(exc).__name__}
            time.sleep(0.1)
        try:
            _write(out, record)
        except (BrokenPipeError, OSError):
            return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
