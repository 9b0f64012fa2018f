#!/usr/bin/env python3
"""A JAX peer of herdfit's model step, for `benches/peers/compare.py`.

The same force model as herdfit (paper eq. 2–6, DESIGN §4) over padded neighbour lists
``[N, K]``: gathers, distances, the unsigned bearing φ = |atan2(h × u, h · u)|, the Gaussian
weights ``w·exp(α d² + γ φ²)`` of cohesion, avoidance and alignment, the direction update of
eq. 2, leaders that take the guidance direction, the OU speed of eq. 6 (no gradient) and the
position update. The scene is herdfit's benchmark scene (``herdfit bench``): one agent per
2 BL², heading +x ± 20°, speeds N(1, 0.2), default parameters, uniform guidance (1, 0), 25 fps,
no obstacles.

Differences from herdfit, all in the peer's favour:
- **No occlusion.** Neighbour lists are the K nearest agents within R_perc (scipy's cKDTree),
  computed outside the differentiated graph by a no-gradient pre-run, like herdfit's replayed
  decisions; their cost is not timed. herdfit's figures include its perception (grid, capsule
  occlusion) on every step.
- The lists, leader flags and noise of all T steps are precomputed; the timed function is
  ``jax.jit(jax.value_and_grad(J))`` over ``lax.scan`` of the T steps (J = herdfit's gradcheck
  objective: the herd's spread / R² + mean heading along (0.6, 0.8)), and ``jax.jit(J)`` for the
  forward alone.

Prints one JSON object per agent count on stdout.
"""

import argparse
import json
import math
import sys
import time

import numpy as np

R_PERC = 4.0
OMEGA = 10.0
DT = 1.0 / 25.0
THETA = [0.3, 0.6, 0.7, 0.6, 0.2, 0.6, 0.5, 0.5, 0.5, 0.7, 0.3, 0.5]
SPEED_MEAN, SPEED_STD, SPEED_MAX, REVERSION = 1.0, 0.2, 3.0, 1.0
LEADER_CONE = math.radians(60.0)
LEADER_MAX = 2
NORM_EPS = 1e-12


def standard_herd(n, rng):
    side = math.sqrt(n / 0.5)
    pos = (rng.random((n, 2)) - 0.5) * side
    ang = np.radians(20.0 * rng.standard_normal(n))
    speed = np.clip(SPEED_MEAN + SPEED_STD * rng.standard_normal(n), 0.0, SPEED_MAX)
    head = np.stack([np.cos(ang), np.sin(ang)], axis=1)
    return pos, head, speed


def neighbour_lists(pos, head, k):
    """K nearest agents within R_perc (self excluded), padded with the agent itself."""
    from scipy.spatial import cKDTree

    n = len(pos)
    dist, idx = cKDTree(pos).query(pos, k=k + 1, distance_upper_bound=R_PERC)
    dist, idx = dist[:, 1:], idx[:, 1:]
    mask = np.isfinite(dist) & (dist > 1e-9)
    idx = np.where(mask, idx, np.arange(n)[:, None])
    # Leader rule: visible neighbours within the front cone (all in range: no occlusion).
    u = pos[idx] - pos[:, None, :]
    dot = head[:, 0:1] * u[..., 0] + head[:, 1:2] * u[..., 1]
    cross = head[:, 0:1] * u[..., 1] - head[:, 1:2] * u[..., 0]
    front = ((np.abs(np.arctan2(cross, dot)) <= LEADER_CONE) & mask).sum(axis=1)
    leader = front <= LEADER_MAX
    return idx.astype(np.int32), mask, leader


def make_step(jnp):
    def coefficients(theta):
        t = theta.reshape(4, 3)
        w = t[:, 0] * OMEGA
        alpha = -0.5 / (t[:, 1] * R_PERC) ** 2
        gamma = -0.5 / (t[:, 2] * math.pi) ** 2
        return w, alpha, gamma

    def step(theta, state, lists):
        x, y, hx, hy, v = state
        idx, mask, leader, xi = lists
        w, alpha, gamma = coefficients(theta)
        dx = x[idx] - x[:, None]
        dy = y[idx] - y[:, None]
        d2 = dx * dx + dy * dy
        dot = hx[:, None] * dx + hy[:, None] * dy + (1.0 - mask)  # guard padding (atan2(0,0))
        cross = hx[:, None] * dy - hy[:, None] * dx
        phi2 = jnp.arctan2(cross, dot) ** 2
        c = [w[g] * jnp.exp(alpha[g] * d2 + gamma[g] * phi2) * mask for g in range(3)]
        cp = c[0] - c[1]
        fx = (cp * dx + c[2] * hx[idx]).sum(axis=1)
        fy = (cp * dy + c[2] * hy[idx]).sum(axis=1)
        ux = v * hx + DT * fx
        uy = v * hy + DT * fy
        norm = jnp.sqrt(ux * ux + uy * uy + NORM_EPS)
        follow = 1.0 - leader
        nhx = ux / norm * follow + leader  # guidance (1, 0)
        nhy = uy / norm * follow
        v1 = v - REVERSION * (v - SPEED_MEAN) * DT + SPEED_STD * math.sqrt(DT) * xi
        v1 = jnp.clip(v1, 0.0, SPEED_MAX)
        return (x + DT * v1 * nhx, y + DT * v1 * nhy, nhx, nhy, v1)

    return step


def objective(jnp, state):
    x, y, hx, hy, _ = state
    spread = ((x - x.mean()) ** 2 + (y - y.mean()) ** 2).mean() / (R_PERC * R_PERC)
    return spread + (0.6 * hx + 0.8 * hy).mean()


def run(n, steps, repeats, k, seed):
    import jax
    import jax.numpy as jnp
    from jax import lax

    rng = np.random.default_rng(seed)
    pos, head, speed = standard_herd(n, rng)
    step = make_step(jnp)
    theta = jnp.asarray(THETA, dtype=jnp.float32)

    # No-gradient pre-run: lists, leaders and noise of every step (outside the graph).
    state = tuple(jnp.asarray(a, dtype=jnp.float32) for a in
                  (pos[:, 0], pos[:, 1], head[:, 0], head[:, 1], speed))
    jstep = jax.jit(step)
    recorded = []
    for _ in range(steps):
        p = np.stack([np.asarray(state[0]), np.asarray(state[1])], axis=1).astype(np.float64)
        h = np.stack([np.asarray(state[2]), np.asarray(state[3])], axis=1).astype(np.float64)
        idx, mask, leader = neighbour_lists(p, h, k)
        xi = rng.standard_normal(n)
        lists = (jnp.asarray(idx), jnp.asarray(mask, dtype=jnp.float32),
                 jnp.asarray(leader, dtype=jnp.float32), jnp.asarray(xi, dtype=jnp.float32))
        recorded.append(lists)
        state = jstep(theta, state, lists)
    stacked = tuple(jnp.stack([r[i] for r in recorded]) for i in range(4))
    init = tuple(jnp.asarray(a, dtype=jnp.float32) for a in
                 (pos[:, 0], pos[:, 1], head[:, 0], head[:, 1], speed))

    def J(theta):
        def body(s, lists):
            return step(theta, s, lists), None

        end, _ = lax.scan(body, init, stacked)
        return objective(jnp, end)

    fwd = jax.jit(J)
    fwd_bwd = jax.jit(jax.value_and_grad(J))

    def timed(f):
        jax.block_until_ready(f(theta))  # compile + warm up
        times = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            jax.block_until_ready(f(theta))
            times.append((time.perf_counter() - t0) * 1e3 / steps)
        return float(np.median(times))

    value, grad = fwd_bwd(theta)
    return {
        "agents": n,
        "steps": steps,
        "k": k,
        "mean_neighbours": float(np.asarray(stacked[1][0]).sum() / n),
        "forward_ms_per_step": timed(fwd),
        "forward_backward_ms_per_step": timed(fwd_bwd),
        "objective": float(value),
        "grad_finite": bool(np.all(np.isfinite(np.asarray(grad)))),
        "jax": jax.__version__,
        "devices": [str(d) for d in jax.devices()],
    }


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--agents", type=int, nargs="+", default=[500, 1500, 5000])
    ap.add_argument("--steps", type=int, default=20)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--k", type=int, default=16, help="padded list width K")
    ap.add_argument("--seed", type=int, default=1)
    a = ap.parse_args()
    if a.steps < 1 or a.repeats < 1 or a.k < 1 or any(n < 2 for n in a.agents):
        sys.exit("error: --steps, --repeats, --k must be ≥ 1 and --agents ≥ 2")
    for n in a.agents:
        print(json.dumps(run(n, a.steps, a.repeats, a.k, a.seed)), flush=True)


if __name__ == "__main__":
    main()
