"""Draws a model's anatomical landmarks (docs/landmarks.md) on two views of its skin, to look at:
the face from the front (the clinical view: the patient's right on the picture's left) and the
patient's left side, each measured skin sample shaded by its depth, each landmark a red cross
with its name and the soft-tissue thickness under it. Absent landmarks are listed with their
reason.

    PYTHONPATH=build/python /usr/bin/python3 examples/landmarks_picture.py MODEL_DIR out.png
"""

import sys
import textwrap

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import caps  # noqa: E402


def skin_points(m):
    """The skin samples as LPS points (n_z, n_theta, 3) and whether each was measured."""
    t = np.radians(m["theta_deg"])[None, :]
    z = m["z_mm"][:, None]
    ax = m["axis"]
    o, d, f = (np.asarray(ax[k], float) for k in ("origin_lps", "direction", "front"))
    left = np.cross(d, f)
    r = m["r_skin"].astype(float)
    ray = np.cos(t)[..., None] * f + np.sin(t)[..., None] * left  # (1, n_theta, 3)
    p = o + z[..., None] * d + r[..., None] * ray
    return p, m["measured_skin"]


def main(model, out, title=None):
    m = caps.load_model(model)
    lm = m["landmarks"] or caps.model_landmarks(model, write=False)
    p, ok = skin_points(m)
    # Lambert shading: the skin's normal from the grid's tangents, lit from the viewer.
    n = np.cross(np.gradient(p, axis=1), np.gradient(p, axis=0))
    n /= np.linalg.norm(n, axis=-1, keepdims=True) + 1e-12
    theta = m["theta_deg"][None, :] + 0 * m["z_mm"][:, None]
    fig, axes = plt.subplots(1, 2, figsize=(12, 7))
    # (title, horizontal and vertical LPS axes, the depth axis and the viewer's side along it)
    views = [("front (patient's right on the left)", 0, 2, 1, -1.0, np.abs(theta) < 100),
             ("patient's left side (face to the left)", 1, 2, 0, 1.0, theta > -10)]
    for a, (name, h, v, depth, viewer, keep) in zip(axes, views):
        sel = keep & ok
        # Draw far samples first so the near ones cover them.
        order = np.argsort(viewer * p[..., depth][sel])
        pts = p[sel][order]
        shade = np.abs(n[sel][order][:, depth])
        a.scatter(pts[:, h], pts[:, v], c=shade, cmap="gray", vmin=0, vmax=1, s=3,
                  linewidths=0)
        for key, l in lm.items():
            if not l["found"]:
                continue
            visible = (h == 0) or key.endswith("_left") or not key.endswith("_right")
            if not visible:
                continue
            x = l["lps"][h]
            a.plot(x, l["lps"][v], "r+", ms=14, mew=2)
            a.annotate(f"{key} {l['thickness_mm']:.1f} mm", (x, l["lps"][v]), color="red",
                       fontsize=8, xytext=(4, 4), textcoords="offset points")
        a.set_aspect("equal")
        a.set_title(name)
        a.set_xlabel("LPS x (mm)" if h == 0 else "anterior <- LPS y (mm) ->  posterior")
        a.set_ylabel("LPS z (mm)")
    # One short line per absent landmark, so that the notes stay inside the picture.
    absent = [textwrap.shorten(f"absent: {k}: {l['note']}", width=150, placeholder=" ...")
              for k, l in lm.items() if not l["found"]]
    fig.suptitle("\n".join([title or str(model)] + absent), fontsize=8)
    fig.tight_layout()
    fig.savefig(out, dpi=90)


if __name__ == "__main__":
    main(*sys.argv[1:4])
