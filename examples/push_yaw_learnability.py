"""How much data does a push's yaw need? A learning curve of a model-free regressor.

A gradient-boosted tree regressor is given each push's exact generator parameters (object shape,
floor and tip friction, speed, approach angle, side and position of the contact) and predicts the
object's yaw after 0.5 s. Under isotropic friction (the elliptic cone of ``generate`` since issue
38) those parameters decide MuJoCo's trajectory in the object's frame completely; under MuJoCo's
default pyramidal cone (``generate --cone pyramidal``, the data of Push-v1) the world heading
``object_yaw0`` changes the turn too (one push: -1.9 to -12.4 deg over 12 headings), so the yaw
is not a function of these parameters and no learner can fit it. Its held-out R^2 against the
number of training pushes says how hard the map is to learn from examples, independently of any
graph network. The last column is in the push target's unit: the median yaw error over that of
not moving (measured figures for both cones: experiments/README.md, "Isotropic physics").

    pip install scikit-learn   # not a fignet_gym dependency
    python examples/push_yaw_learnability.py --train data/push_train.h5 data/push_train8k.h5 \\
        --test data/push_test400.h5 --sizes 1000 2000 4000 10000 [--loss absolute_error]
"""

from __future__ import annotations

import argparse

import numpy as np

from fignet_gym.data.format import load_trajectories
from fignet_gym.envs.base import wrap_angle, yaw_of

STEPS = 25  # 0.5 s at dt = 0.02 s, the push target's horizon
PARAMS = ("friction", "tip_friction", "speed_mm_s", "angle_deg", "position")


def push_table(paths: list[str], shapes: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """Generator parameters ``float[B, 7]`` (shape index, the ``PARAMS``, side) and yaw change
    (deg) of the pushed object from the last history pose to ``STEPS`` steps later, ``float[B]``."""
    x, y = [], []
    for path in paths:
        for t in load_trajectories(path):
            m, o = t.metadata, list(t.names).index("object")
            if m["shape"] not in shapes:
                shapes.append(m["shape"])
            y.append(np.degrees(wrap_angle(yaw_of(t.poses[2 + STEPS, o, 3:]) - yaw_of(t.poses[2, o, 3:]))))
            x.append([shapes.index(m["shape"]), *(m[k] for k in PARAMS), m["side"]])
    return np.asarray(x, dtype=np.float64), np.asarray(y)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--train", nargs="+", required=True, help="push trajectory files (pooled)")
    p.add_argument("--test", required=True)
    p.add_argument("--sizes", nargs="+", type=int, default=[500, 1000, 2000])
    p.add_argument("--seeds", type=int, default=2, help="random training subsets per size")
    p.add_argument("--loss", default="squared_error", choices=["squared_error", "absolute_error"],
                   help="absolute_error fits the median, the statistic the push target is scored on")
    args = p.parse_args()
    try:
        from sklearn.ensemble import HistGradientBoostingRegressor
    except ImportError as e:
        raise SystemExit("this diagnostic needs scikit-learn: pip install scikit-learn") from e
    shapes: list[str] = []
    x_tr, y_tr = push_table(args.train, shapes)
    x_te, y_te = push_table([args.test], shapes)
    print(f"{len(y_tr)} training pushes, {len(y_te)} test pushes; "
          f"test yaw after {STEPS} steps: median |yaw| {np.median(np.abs(y_te)):.2f} deg")
    # The push target's unit: median yaw error over the median error of not moving (|yaw|).
    print(f"{'pushes':>7s} {'R^2':>6s} {'slope':>6s} {'corr':>6s} {'vs still':>8s}")
    for n in args.sizes:
        if n > len(y_tr):
            print(f"{n:7d}  (only {len(y_tr)} training pushes)")
            continue
        stats = []
        for seed in range(args.seeds):
            idx = np.random.default_rng(seed).permutation(len(y_tr))[:n]
            reg = HistGradientBoostingRegressor(loss=args.loss, max_iter=1000, categorical_features=[0, 6],
                                                random_state=seed)
            pred = reg.fit(x_tr[idx], y_tr[idx]).predict(x_te)
            r2 = 1 - ((pred - y_te) ** 2).sum() / ((y_te - y_te.mean()) ** 2).sum()
            still = np.median(np.abs(pred - y_te)) / np.median(np.abs(y_te))
            stats.append((r2, np.polyfit(y_te, pred, 1)[0], np.corrcoef(y_te, pred)[0, 1], still))
        r2, slope, corr, still = np.mean(stats, axis=0)
        print(f"{n:7d} {r2:6.3f} {slope:6.3f} {corr:6.3f} {still:8.3f}")


if __name__ == "__main__":
    main()
