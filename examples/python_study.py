"""A small study from Python: the closing force of a Z-plasty on the phantom head as its angle
is swept (docs/python.md).

    PYTHONPATH=build/python /usr/bin/python3 examples/python_study.py --work /tmp/study
    PYTHONPATH=build/python /usr/bin/python3 examples/python_study.py --angles 45,60 --length 15

Builds the phantom CT and its model once (reused when the folder already holds them), plans a
Z-plasty at each angle at the same place, simulates each closure and prints one row per angle:
the closing force (N), the largest single-suture force at the default suture spacing (N), the
largest displacement (mm) and how many warnings the run gave.
"""

import argparse
import os
import warnings

import numpy as np

import caps


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--work", default=os.path.join(os.environ.get("TMPDIR", "/tmp"), "caps_study"),
                   help="folder for the phantom, the model, the plans and the simulations")
    p.add_argument("--angles", default="30,45,60,75,90", help="Z-plasty angles, deg")
    p.add_argument("--length", type=float, default=15.0, help="central limb length, mm")
    p.add_argument("--at", default="0,60", help="the centre on the skin: THETA,Z (deg, mm)")
    p.add_argument("--mesh-size", type=float, default=2.5, help="mesh size at the wound, mm")
    args = p.parse_args()

    os.makedirs(args.work, exist_ok=True)
    ct = os.path.join(args.work, "ct.nii.gz")
    model = os.path.join(args.work, "model")
    if not os.path.exists(ct):
        caps.phantom(ct, voxels="96,96,90", spacing="2.5,2.5,2.5")
    if not os.path.exists(model):
        caps.model_from_volume(ct, model, n_theta=128, n_z=64)

    # The soft tissue under the site, from the thickness map (mm).
    m = caps.load_model(model)
    theta, z = (float(v) for v in args.at.split(","))
    j = int(np.argmin(np.abs(m["theta_deg"] - theta)))
    k = int(np.argmin(np.abs(m["z_mm"] - z)))
    print(f"phantom model: soft tissue {m['thickness'][k, j]:.2f} mm thick at {args.at}")

    print(f"{'angle (deg)':>11} {'closing force (N)':>18} {'max suture (N)':>15} "
          f"{'max disp. (mm)':>15}  warnings")
    for angle in (float(a) for a in args.angles.split(",")):
        name = f"z{angle:g}"
        plan = os.path.join(args.work, name + ".json")
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", caps.CapsWarning)  # they are in the results
            try:
                caps.plan_new("z-plasty", model=model, output=plan, at=args.at, force=True,
                              parameters={"length": args.length, "angle": angle})
                r = caps.simulate(model, plan, os.path.join(args.work, name),
                                  mesh_size=args.mesh_size, force=True)
            except caps.Error as e:
                print(f"{angle:11g}  failed: {e}")
                continue
        print(f"{angle:11g} {r['closing_force_n']:18.3f} "
              f"{r['sutures_at_spacing']['max_force_per_suture_n']:15.3f} "
              f"{r['max_displacement_mm']:15.2f}  {len(r['warnings'])}")


if __name__ == "__main__":
    main()
