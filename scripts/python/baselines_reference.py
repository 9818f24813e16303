#!/usr/bin/env python3
"""Reference numbers for tendril's baseline learners from scikit-learn / numpy.

Reads the normalised splits that `tendril compare --dump-splits DIR` writes
(fit.csv, valid.csv, test.csv: columns x0..x6 then y0..y3, all in the
training split's [0, 1] ranges), fits each baseline with the hyper-parameters
tendril chose (pass them on the command line, see --help) and prints the test
tension RMSE in normalised units x100, the scale of tendril's compare.md.

Local check only (not run in CI):
    pip install scikit-learn numpy
    python3 scripts/python/baselines_reference.py --splits out/splits \
        --knn-k 5 --knn-weights distance --tree-depth 14 --tree-min-leaf 2 \
        --elm-hidden 1500 --elm-ridge 1e-8 --elm-scale 4 \
        --rbf-centres 800 --rbf-width 1 --rbf-ridge 1e-10 \
        --mlp-hidden 64 --mlp-epochs 150 --mlp-batch 32 --mlp-lr 3e-3
"""

import argparse
import math
import time

import numpy as np


def load(path):
    with open(path) as f:
        header = f.readline().strip().split(",")
    data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    xs = [i for i, h in enumerate(header) if h.startswith("x")]
    ys = [i for i, h in enumerate(header) if h.startswith("y")]
    return data[:, xs], data[:, ys]


def rmse100(pred, y):
    return 100.0 * math.sqrt(np.mean((pred - y) ** 2))


def ridge_solve(a, y, ridge):
    """Same ridge as tendril: lambda scaled by the Gram matrix's mean diagonal."""
    g = a.T @ a
    scale = np.trace(g) / g.shape[0]
    g[np.diag_indices_from(g)] += ridge * scale
    return np.linalg.solve(g, a.T @ y)


def elm(tx, ty, sx, hidden, ridge, scale, seed):
    rng = np.random.default_rng(seed)
    w = scale * rng.uniform(-1, 1, (tx.shape[1], hidden))
    b = scale * rng.uniform(-1, 1, hidden)

    def feats(x):
        h = 1.0 / (1.0 + np.exp(-(x @ w + b)))
        return np.hstack([h, np.ones((x.shape[0], 1))])

    out = ridge_solve(feats(tx), ty, ridge)
    return feats(sx) @ out


def elm_lstsq(tx, ty, sx, hidden, scale, seed):
    """Plain numpy lstsq (no ridge), as a second reference."""
    rng = np.random.default_rng(seed)
    w = scale * rng.uniform(-1, 1, (tx.shape[1], hidden))
    b = scale * rng.uniform(-1, 1, hidden)

    def feats(x):
        h = 1.0 / (1.0 + np.exp(-(x @ w + b)))
        return np.hstack([h, np.ones((x.shape[0], 1))])

    out, *_ = np.linalg.lstsq(feats(tx), ty, rcond=None)
    return feats(sx) @ out


def rbf(tx, ty, sx, centres, width, ridge, seed):
    from sklearn.cluster import KMeans

    sub = tx
    if tx.shape[0] > 6000:
        idx = np.random.default_rng(seed).choice(tx.shape[0], 6000, replace=False)
        sub = tx[idx]
    km = KMeans(n_clusters=centres, n_init=1, max_iter=15, random_state=seed).fit(sub)
    c = km.cluster_centers_
    d2 = ((c[:, None, :] - c[None, :, :]) ** 2).sum(-1)
    np.fill_diagonal(d2, np.inf)
    sigma = width * np.sqrt(d2.min(1)).mean()

    def feats(x):
        d = ((x[:, None, :] - c[None, :, :]) ** 2).sum(-1)
        return np.hstack([np.exp(-d / (2 * sigma * sigma)), np.ones((x.shape[0], 1))])

    out = ridge_solve(feats(tx), ty, ridge)
    return feats(sx) @ out


def mlp(tx, ty, vx, vy, sx, hidden, epochs, batch, lr, final_fraction, eval_every, seed):
    """sklearn MLPRegressor, one Adam epoch per partial_fit so the cosine
    learning-rate decay and best-on-validation weights match tendril's."""
    import copy

    from sklearn.neural_network import MLPRegressor

    m = MLPRegressor(
        hidden_layer_sizes=tuple(hidden),
        activation="tanh",
        solver="adam",
        alpha=0.0,
        batch_size=batch,
        learning_rate_init=lr,
        shuffle=True,
        random_state=seed,
    )
    lo = lr * final_fraction
    best = (math.inf, None)
    for e in range(epochs):
        if e > 0:
            m._optimizer.learning_rate_init = lo + 0.5 * (lr - lo) * (1 + math.cos(math.pi * e / epochs))
        m.partial_fit(tx, ty)
        if (e + 1) % eval_every == 0 or e + 1 == epochs:
            s = rmse100(m.predict(vx), vy)
            if s < best[0]:
                best = (s, copy.deepcopy(m))
    return best[1].predict(sx)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--splits", required=True)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--knn-k", type=int)
    ap.add_argument("--knn-weights", choices=["uniform", "distance"], default="uniform")
    ap.add_argument("--tree-depth", type=int)
    ap.add_argument("--tree-min-leaf", type=int, default=1)
    ap.add_argument("--elm-hidden", type=int)
    ap.add_argument("--elm-ridge", type=float, default=1e-8)
    ap.add_argument("--elm-scale", type=float, default=1.0)
    ap.add_argument("--rbf-centres", type=int)
    ap.add_argument("--rbf-width", type=float, default=1.0)
    ap.add_argument("--rbf-ridge", type=float, default=1e-10)
    ap.add_argument("--mlp-hidden", type=lambda s: [int(v) for v in s.split("-")])
    ap.add_argument("--mlp-epochs", type=int, default=150)
    ap.add_argument("--mlp-batch", type=int, default=32)
    ap.add_argument("--mlp-lr", type=float, default=3e-3)
    ap.add_argument("--mlp-final-fraction", type=float, default=0.01)
    ap.add_argument("--mlp-eval-every", type=int, default=5)
    a = ap.parse_args()

    tx, ty = load(f"{a.splits}/fit.csv")
    vx, vy = load(f"{a.splits}/valid.csv")
    sx, sy = load(f"{a.splits}/test.csv")
    print(f"fit {tx.shape}, valid {vx.shape}, test {sx.shape}")

    def report(name, fn):
        t = time.time()
        pred = fn()
        print(f"{name:28s} test RMSE x100 = {rmse100(pred, sy):.4f}   ({time.time() - t:.1f} s)")

    if a.knn_k:
        from sklearn.neighbors import KNeighborsRegressor

        report(
            f"KNN k={a.knn_k} {a.knn_weights}",
            lambda: KNeighborsRegressor(n_neighbors=a.knn_k, weights=a.knn_weights).fit(tx, ty).predict(sx),
        )
    if a.tree_depth:
        from sklearn.tree import DecisionTreeRegressor

        report(
            f"tree depth={a.tree_depth} leaf={a.tree_min_leaf}",
            lambda: DecisionTreeRegressor(
                max_depth=a.tree_depth, min_samples_leaf=a.tree_min_leaf, random_state=a.seed
            )
            .fit(tx, ty)
            .predict(sx),
        )
    if a.elm_hidden:
        report(
            f"ELM h={a.elm_hidden} ridge",
            lambda: elm(tx, ty, sx, a.elm_hidden, a.elm_ridge, a.elm_scale, a.seed),
        )
        report(f"ELM h={a.elm_hidden} lstsq", lambda: elm_lstsq(tx, ty, sx, a.elm_hidden, a.elm_scale, a.seed))
    if a.rbf_centres:
        report(
            f"RBF c={a.rbf_centres}",
            lambda: rbf(tx, ty, sx, a.rbf_centres, a.rbf_width, a.rbf_ridge, a.seed),
        )
    if a.mlp_hidden:
        report(
            f"MLP {a.mlp_hidden} Adam",
            lambda: mlp(
                tx,
                ty,
                vx,
                vy,
                sx,
                a.mlp_hidden,
                a.mlp_epochs,
                a.mlp_batch,
                a.mlp_lr,
                a.mlp_final_fraction,
                a.mlp_eval_every,
                a.seed,
            ),
        )


if __name__ == "__main__":
    main()
