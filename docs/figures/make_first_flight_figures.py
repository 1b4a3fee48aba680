"""The pictures of docs/first-flight.md, drawn with matplotlib (the 'plot' extra):

* ``body-axes.png`` — the world and body axes and the sign of every angle: the mocap frame
  (x forward, y left, z up, ψ counter-clockwise), navdata's roll and pitch, the thesis' φ, θ;
* ``network.png`` — the laptop on the drone's Wi-Fi and wired to the mocap PC, with the ports
  and the route to check.

    python docs/figures/make_first_flight_figures.py [OUT_DIR]   # default: docs/figures

tests/unit/test_first_flight_figures.py runs it and checks what it draws.
"""

from __future__ import annotations

import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.patches import Circle, FancyArrowPatch, FancyBboxPatch, Polygon  # noqa: E402

FIGURES = ("body-axes.png", "network.png")
RED, GREEN, BLUE, GREY = "#d62728", "#2ca02c", "#1f77b4", "#7f7f7f"
DPI = 110


def _arrow(ax, start, end, color, label=None, label_at=1.12, **kw):
    ax.add_patch(FancyArrowPatch(start, end, arrowstyle="-|>", mutation_scale=18,
                                 color=color, lw=2.2, **kw))
    if label:
        x = start[0] + (end[0] - start[0]) * label_at
        y = start[1] + (end[1] - start[1]) * label_at
        ax.text(x, y, label, color=color, ha="center", va="center", fontsize=11,
                fontweight="bold")


def _quad_top(ax):
    """An AR.Drone seen from above, nose towards +x (up the page)."""
    for dx, dy in ((0.55, 0.55), (0.55, -0.55), (-0.55, 0.55), (-0.55, -0.55)):
        ax.add_patch(Circle((dy * -1, dx), 0.32, fill=False, lw=1.5, color=GREY))
        ax.plot([0, -dy * 0.9], [0, dx * 0.9], color=GREY, lw=3)
    ax.add_patch(FancyBboxPatch((-0.22, -0.35), 0.44, 0.7, boxstyle="round,pad=0.05",
                                color="#cccccc", ec=GREY))
    ax.add_patch(Polygon([(-0.1, 0.38), (0.1, 0.38), (0, 0.5)], color="black"))
    ax.text(0.12, 1.0, "nose\n(front camera)", ha="left", fontsize=8)


def _top_view(ax):
    ax.set_title("seen from above: the world (mocap) frame", fontsize=11)
    _quad_top(ax)
    # the page: x up, y left — a right-handed frame with z out of the page
    _arrow(ax, (0, 0), (0, 1.5), RED, "+x forward", label_at=1.1)
    _arrow(ax, (0, 0), (-1.5, 0), GREEN, "+y left", label_at=1.2)
    ax.add_patch(Circle((0, 0), 0.08, color=BLUE))
    ax.text(0.2, -0.12, "+z up (towards you)", color=BLUE, fontsize=9)
    ax.add_patch(FancyArrowPatch((1.35, 0.1), (0.9, 1.2), connectionstyle="arc3,rad=0.35",
                                 arrowstyle="-|>", mutation_scale=16, color="black", lw=1.8))
    ax.text(1.3, 1.1, "ψ > 0\ncounter-\nclockwise", fontsize=9)
    ax.text(0, -1.45, "ψ = 0: the nose along +x\nnavdata yaw > 0 is clockwise (−ψ)",
            ha="center", fontsize=9)
    ax.set_xlim(-1.9, 1.9)
    ax.set_ylim(-1.75, 1.9)


def _side(ax, title, tilt_deg, left_label, right_label, up_label, notes, arrow_text,
          arrow_up):
    """A drone seen edge-on, tilted by ``tilt_deg`` (positive: its right end lower); the
    curved arrow at the right end shows which way that end turns for a positive angle."""
    import math

    ax.set_title(title, fontsize=11)
    t = math.radians(tilt_deg)
    c, s = math.cos(t), math.sin(t)
    normal = (s, c)            # the body's z axis: perpendicular to the arms, upwards
    ends = [(-1.0 * c, 1.0 * s), (1.0 * c, -1.0 * s)]
    ax.plot([ends[0][0], ends[1][0]], [ends[0][1], ends[1][1]], color=GREY, lw=6,
            solid_capstyle="round")
    for (x, y) in ends:        # the rotors, above the arms along the body's z
        cx, cy = x + 0.2 * normal[0], y + 0.2 * normal[1]
        ax.plot([cx - 0.25 * c, cx + 0.25 * c], [cy + 0.25 * s, cy - 0.25 * s], color=GREY,
                lw=2)
    ax.plot([-1.5, 1.5], [0, 0], ls=":", color=GREY, lw=1)
    ax.text(ends[0][0] - 0.1, ends[0][1] + 0.45, left_label, ha="center", fontsize=9)
    ax.text(ends[1][0] + 0.1, ends[1][1] + (0.45 if ends[1][1] > 0 else -0.5), right_label,
            ha="center", fontsize=9)
    _arrow(ax, (0, 0), (0.9 * normal[0], 0.9 * normal[1]), BLUE, up_label, label_at=1.25)
    start, end = ((1.2, -0.45), (1.25, 0.2)) if arrow_up else ((1.25, 0.2), (1.2, -0.45))
    ax.add_patch(FancyArrowPatch(start, end, connectionstyle="arc3,rad=-0.3"
                                 if not arrow_up else "arc3,rad=0.3",
                                 arrowstyle="-|>", mutation_scale=14, color="black", lw=1.5))
    ax.text(1.5, -0.15, arrow_text, fontsize=9, va="center")
    ax.text(0, -1.25, notes, ha="center", va="top", fontsize=9)
    ax.set_xlim(-1.9, 2.3)
    ax.set_ylim(-2.0, 1.6)


def body_axes(path: Path) -> None:
    fig, axes = plt.subplots(1, 3, figsize=(13.5, 5.2))
    for ax in axes:
        ax.set_aspect("equal")
        ax.axis("off")
    _top_view(axes[0])
    _side(axes[1], "seen from behind: roll", 15, "left rotors\n(+y)", "right rotors",
          "body z", "navdata roll > 0: right side down\n= thesis φ > 0 (accelerates to −y)\n"
          "= PCMD roll > 0", "roll > 0", arrow_up=False)
    _side(axes[2], "seen from the left side: pitch", -15, "tail", "nose (+x)",
          "body z", "navdata pitch > 0: nose UP\nthesis θ > 0: nose DOWN (accelerates to +x)\n"
          "θ = −navdata pitch;  PCMD pitch = −θ/E", "nose up:\npitch > 0", arrow_up=True)
    fig.suptitle("ardrone-nmpc frames: world x forward, y left, z up (metres); the mocap "
                 "object's axes must be the drone's", fontsize=12)
    fig.tight_layout()
    fig.savefig(path, dpi=DPI)
    plt.close(fig)


def _box(ax, xy, w, h, title, lines, color):
    ax.add_patch(FancyBboxPatch(xy, w, h, boxstyle="round,pad=0.02", fc=color, ec="black",
                                alpha=0.9))
    ax.text(xy[0] + w / 2, xy[1] + h - 0.08, title, ha="center", va="top", fontsize=11,
            fontweight="bold")
    ax.text(xy[0] + w / 2, xy[1] + h - 0.32, "\n".join(lines), ha="center", va="top",
            fontsize=8.5, linespacing=1.35)


def _link(ax, a, b, text, color, style="-", offset=(0, 0.06)):
    ax.annotate("", xy=b, xytext=a, arrowprops=dict(arrowstyle="<|-|>", color=color, lw=2.2,
                                                    linestyle=style))
    ax.text((a[0] + b[0]) / 2 + offset[0], (a[1] + b[1]) / 2 + offset[1], text, ha="center",
            va="bottom", fontsize=8.5, color=color)


def network(path: Path) -> None:
    fig, ax = plt.subplots(figsize=(12.5, 4.9))
    ax.set_xlim(0, 12.5)
    ax.set_ylim(0.2, 5.1)
    ax.axis("off")
    _box(ax, (0.3, 3.0), 3.0, 2.0, "AR.Drone 2.0", [
        "192.168.1.1 (its own Wi-Fi, ardrone2_…)", "UDP 5556  AT commands (in)",
        "UDP 5554  navdata (out)", "TCP 5559  config read-back",
        "markers: rigid body 'ardrone'"], "#fde0c5")
    _box(ax, (4.75, 2.55), 3.0, 2.45, "laptop: ardrone-nmpc", [
        "wlan0: 192.168.1.x (DHCP from the drone)", "Wi-Fi power saving OFF",
        "eth0: the mocap subnet (NOT 192.168.1.x)", "ip route get 192.168.1.1 → dev wlan0",
        "UDP 51001  Vicon UDP stream (in)", "Foxglove: ws://127.0.0.1:8765 (local)"],
        "#d9ead3")
    _box(ax, (9.2, 3.0), 3.0, 2.0, "mocap PC", [
        "Vicon Tracker: UDP object stream,", "destination = laptop eth0 : 51001",
        "or a libmotioncapture server:", "Vicon DataStream, OptiTrack NatNet,",
        "Qualisys, VRPN (mocap.hostname)"], "#cfe2f3")
    _link(ax, (3.3, 4.0), (4.75, 4.0), "Wi-Fi\nAT, navdata, config", RED)
    _link(ax, (7.75, 4.0), (9.2, 4.0), "Ethernet (wired)\nposes ≈ 100 Hz", BLUE)
    ax.annotate("", xy=(1.8, 2.95), xytext=(10.7, 2.95),
                arrowprops=dict(arrowstyle="-|>", color=GREY, lw=1.2, linestyle="--",
                                connectionstyle="arc3,rad=-0.22"))
    ax.text(6.25, 1.55, "the cameras see the markers on the drone", ha="center",
            fontsize=8.5, color=GREY)
    ax.text(6.25, 0.35, "Two networks, two interfaces: the drone's Wi-Fi (192.168.1.0/24) and "
            "the wired mocap network on another subnet.\nCheck with `ip route get 192.168.1.1`"
            " (must name the Wi-Fi interface) and `ardrone-nmpc status`, then "
            "`ardrone-nmpc mocap-check CONFIG`.", ha="center", fontsize=9.5)
    fig.tight_layout()
    fig.savefig(path, dpi=DPI)
    plt.close(fig)


def main(out_dir: Path) -> list[Path]:
    out_dir.mkdir(parents=True, exist_ok=True)
    body_axes(out_dir / FIGURES[0])
    network(out_dir / FIGURES[1])
    return [out_dir / name for name in FIGURES]


if __name__ == "__main__":
    for written in main(Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).parent):
        print(written)
