"""The statics of docs/design.md §2 written in plain numpy, for two jobs:

* the yardstick of the issue's speed target (``robot.fk`` against a pure-numpy
  implementation of the same model, see ``fk_vs_numpy.py``);
* an independent implementation the tests compare ``robot.fk`` with
  (``python/tests/test_numpy_model.py``).

It covers what the default robot needs — straight tendons anchored at the tip,
gravity, no tip wrench — and nothing more. It shares no code with tendril: the
same equations (Rucker & Webster 2011, eqs. 13–17, in the symbols of §2), the
same discretisation (classical RK4, a fixed number of steps over the length,
state p, R, w = v − e3, u), and the shooting method the public C++ reference
uses (Newton on x = [n(0); u(0)] with a forward-difference Jacobian).
"""

import tomllib

import numpy as np


def hat(x):
    """The skew matrix of x: hat(x) @ y == cross(x, y)."""
    return np.array([[0.0, -x[2], x[1]], [x[2], 0.0, -x[0]], [-x[1], x[0], 0.0]])


class NumpyRod:
    """A straight-tendon, tip-anchored Cosserat rod from a tendril robot file."""

    def __init__(self, toml_text: str, steps: int = 16):
        spec = tomllib.loads(toml_text)
        bb = spec["backbone"]
        for t in spec["tendon"]:
            if t.get("routing", "straight") != "straight" or t.get("end", bb["length"]) != bb["length"]:
                raise ValueError("numpy_model covers straight tendons anchored at the tip only")
        radius = bb["radius"]
        area = np.pi * radius**2
        inertia = np.pi * radius**4 / 4.0
        e, g = bb["youngs_modulus"], bb["shear_modulus"]
        self.length = bb["length"]
        self.steps = steps
        self.kse = np.array([g * area, g * area, e * area])
        self.kbt = np.array([e * inertia, e * inertia, g * 2.0 * inertia])
        gravity = np.array(spec.get("environment", {}).get("gravity", [0.0, 0.0, 0.0]))
        self.f_e = bb["density"] * area * gravity
        self.r = [t["offset"] * np.array([np.cos(np.radians(t["angle_deg"])),
                                          np.sin(np.radians(t["angle_deg"])), 0.0])
                  for t in spec["tendon"]]
        self.tau = np.zeros(len(self.r))

    # -- the strain rates (§2: the 6x6 system) ---------------------------------
    def rates(self, state):
        p, rot, w, u = state
        v = w + np.array([0.0, 0.0, 1.0])
        n = self.kse * w
        m = self.kbt * u
        uh = hat(u)
        big_a = np.zeros((3, 3))
        big_g = np.zeros((3, 3))
        big_h = np.zeros((3, 3))
        a = np.zeros(3)
        b = np.zeros(3)
        for tau, r in zip(self.tau, self.r):
            if tau == 0.0:
                continue
            q = uh @ r + v
            qh = hat(q)
            a_i = -tau * (qh @ qh) / np.linalg.norm(q) ** 3
            rh = hat(r)
            g_i = -a_i @ rh
            big_a += a_i
            big_g += g_i
            big_h += rh @ g_i
            a_vec = a_i @ (uh @ q)
            a += a_vec
            b += rh @ a_vec
        k = np.block([[np.diag(self.kse) + big_a, big_g], [big_g.T, np.diag(self.kbt) + big_h]])
        rhs = np.concatenate([-uh @ n - rot.T @ self.f_e - a, -uh @ m - hat(v) @ n - b])
        dv_du = np.linalg.solve(k, rhs)
        return rot @ v, rot @ uh, dv_du[:3], dv_du[3:]

    def integrate(self, x):
        """Base wrench guess x = [n(0); u(0)] -> the tip state."""
        state = (np.zeros(3), np.eye(3), x[:3] / self.kse, x[3:].copy())
        h = self.length / self.steps
        for _ in range(self.steps):
            k1 = self.rates(state)
            k2 = self.rates(tuple(s + 0.5 * h * d for s, d in zip(state, k1)))
            k3 = self.rates(tuple(s + 0.5 * h * d for s, d in zip(state, k2)))
            k4 = self.rates(tuple(s + h * d for s, d in zip(state, k3)))
            state = tuple(s + h / 6.0 * (d1 + 2.0 * d2 + 2.0 * d3 + d4)
                          for s, d1, d2, d3, d4 in zip(state, k1, k2, k3, k4))
        return state

    def residual(self, x):
        """The tip boundary condition of §2 (no tip wrench), body frame."""
        p, rot, w, u = self.integrate(x)
        v = w + np.array([0.0, 0.0, 1.0])
        force = -self.kse * w
        moment = -self.kbt * u
        for tau, r in zip(self.tau, self.r):
            q = hat(u) @ r + v
            f_i = -tau * q / np.linalg.norm(q)
            force = force + f_i
            moment = moment + np.cross(r, f_i)
        return np.concatenate([force, moment])

    def initial_guess(self):
        """The tendons' tip loads and the straight rod's weight carried to the base."""
        n0 = self.f_e * self.length + np.array([0.0, 0.0, -self.tau.sum()])
        m0 = np.cross([0.0, 0.0, 0.5 * self.length**2], self.f_e)
        for tau, r in zip(self.tau, self.r):
            m0 = m0 + np.cross(r, [0.0, 0.0, -tau])
        return np.concatenate([n0, m0 / self.kbt])

    def solve(self, tensions, tol=5e-10, max_iterations=60):
        """Tensions (N) -> tip position (m), by Newton with a forward-difference Jacobian."""
        self.tau = np.asarray(tensions, dtype=float)
        x = self.initial_guess()
        scale = np.concatenate([np.full(3, 1e-6), np.full(3, 1e-6)])
        for _ in range(max_iterations):
            r = self.residual(x)
            if np.linalg.norm(r) < tol:
                return self.integrate(x)[0]
            jac = np.empty((6, 6))
            for j in range(6):
                dx = np.zeros(6)
                dx[j] = scale[j] * max(1.0, abs(x[j]))
                jac[:, j] = (self.residual(x + dx) - r) / dx[j]
            x = x - np.linalg.solve(jac, r)
        raise RuntimeError(f"numpy model did not converge for tensions {list(self.tau)}")
