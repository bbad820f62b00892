"""Lane keeping assist (LKA) plant from the MATLAB Reinforcement Learning Toolbox example.

The plant is the linear lateral bicycle model used by MATLAB's LKA examples, extended by the
lateral-error kinematics and the two error integrals that the agent observes:

    d vy/dt  = a1 vy + a2 r + b1 u                        (lateral velocity, body frame)
    d r/dt   = a3 vy + a4 r + b2 u                        (yaw rate)
    d e1/dt  = vy + Vx e2                                 (lateral deviation from the centre line)
    d e2/dt  = r - Vx rho                                 (relative yaw angle; the road curvature rho
                                                           enters as the disturbance -Vx rho)
    d ie1/dt = e1,   d ie2/dt = e2                        (time integrals, observed by the agent)

with a1 = -(2Cf + 2Cr)/(m Vx), a2 = -(2Cf lf - 2Cr lr)/(m Vx) - Vx, a3 = -(2Cf lf - 2Cr lr)/(Iz Vx),
a4 = -(2Cf lf^2 + 2Cr lr^2)/(Iz Vx), b1 = 2Cf/m, b2 = 2Cf lf/Iz (two tyres per axle, as in MATLAB).

The steering u is held constant over each sample (zero-order hold) and rho is constant, so the
6-state system is discretised *exactly*: the augmented matrix [[A, B, E], [0, 0, 0]] * Ts is
exponentiated once at construction (pure numpy, scaling and squaring of a Taylor series) and each
step is one 6x6 matrix-vector product.

Room: actors, the env-running component. May import: the contract and laneshift.actors; never
another component.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces


@dataclass(frozen=True)
class LKAParams:
    """Vehicle and task parameters of the MATLAB example (SI units)."""

    m: float = 1575.0  # total vehicle mass [kg]
    Iz: float = 2875.0  # yaw moment of inertia [m N s^2]
    lf: float = 1.2  # CoG to front axle [m]
    lr: float = 1.6  # CoG to rear axle [m]
    Cf: float = 19000.0  # front cornering stiffness [N/rad]
    Cr: float = 33000.0  # rear cornering stiffness [N/rad]
    Vx: float = 15.0  # longitudinal speed [m/s]
    Ts: float = 0.1  # sample time [s]
    rho: float = 0.001  # road curvature [1/m]
    u_limit: float = 0.5  # physical steering limit [rad]


def expm(a: np.ndarray) -> np.ndarray:
    """Matrix exponential by scaling and squaring of a truncated Taylor series.

    The matrix is scaled by 2**-s so that its infinity norm is below 0.5; 30 Taylor terms of the
    scaled matrix then have a truncation error far below double precision (0.5**31 / 31!), and the
    result is squared s times.  Adequate for the small, well-conditioned matrices used here; scipy
    is deliberately not a dependency.
    """
    a = np.asarray(a, dtype=np.float64)
    if a.ndim != 2 or a.shape[0] != a.shape[1]:
        raise ValueError(f"expm needs a square matrix, got shape {a.shape}")
    norm = float(np.max(np.sum(np.abs(a), axis=1))) if a.size else 0.0
    s = max(0, int(np.ceil(np.log2(norm / 0.5)))) if norm > 0.5 else 0
    scaled = a / (2.0**s)
    result = np.eye(a.shape[0])
    term = np.eye(a.shape[0])
    for k in range(1, 31):
        term = term @ scaled / k
        result = result + term
    for _ in range(s):
        result = result @ result
    return result


def continuous_model(p: LKAParams = LKAParams()) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Continuous-time (A, B, E) of the 6-state plant x = [vy, r, e1, e2, ie1, ie2].

    dx/dt = A x + B u + E rho, with u the front steering angle [rad] and rho the road curvature.
    """
    m, Iz, lf, lr, Cf, Cr, Vx = p.m, p.Iz, p.lf, p.lr, p.Cf, p.Cr, p.Vx
    a1 = -(2 * Cf + 2 * Cr) / m / Vx
    a2 = -(2 * Cf * lf - 2 * Cr * lr) / m / Vx - Vx
    a3 = -(2 * Cf * lf - 2 * Cr * lr) / Iz / Vx
    a4 = -(2 * Cf * lf**2 + 2 * Cr * lr**2) / Iz / Vx
    b1 = 2 * Cf / m
    b2 = 2 * Cf * lf / Iz
    A = np.array(
        [
            [a1, a2, 0, 0, 0, 0],
            [a3, a4, 0, 0, 0, 0],
            [1, 0, 0, Vx, 0, 0],
            [0, 1, 0, 0, 0, 0],
            [0, 0, 1, 0, 0, 0],
            [0, 0, 0, 1, 0, 0],
        ],
        dtype=np.float64,
    )
    B = np.array([b1, b2, 0, 0, 0, 0], dtype=np.float64)
    E = np.array([0, 0, 0, -Vx, 0, 0], dtype=np.float64)
    return A, B, E


def discrete_model(p: LKAParams = LKAParams()) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Exact zero-order-hold discretisation (Ad, Bd, Ed) for sample time p.Ts.

    x[k+1] = Ad x[k] + Bd u[k] + Ed rho.  Both inputs are piecewise constant, so the exponential of
    the augmented matrix [[A, B, E], [0, 0, 0]] Ts holds all three blocks.
    """
    A, B, E = continuous_model(p)
    n = A.shape[0]
    aug = np.zeros((n + 2, n + 2))
    aug[:n, :n] = A
    aug[:n, n] = B
    aug[:n, n + 1] = E
    phi = expm(aug * p.Ts)
    return phi[:n, :n].copy(), phi[:n, n].copy(), phi[:n, n + 1].copy()


#: Discrete steering actions of the MATLAB example: -15, -14, ..., 15 degrees (31 actions).
LKA_STEERING_DEG: tuple[int, ...] = tuple(range(-15, 16))
#: Same, in radians, indexed by action.
LKA_STEERING_RAD: np.ndarray = np.deg2rad(np.array(LKA_STEERING_DEG, dtype=np.float64))

#: Reward weights: r = -(10 e1^2 + 5 e2^2 + 2 u^2 + 5 de1^2 + 5 de2^2).
LKA_REWARD_WEIGHTS = {"e1": 10.0, "e2": 5.0, "u": 2.0, "de1": 5.0, "de2": 5.0}


def lka_reward_terms(e1: float, e2: float, u: float, de1: float, de2: float) -> dict[str, float]:
    """Per-term breakdown of the MATLAB reward (each term is <= 0); their sum is the reward."""
    w = LKA_REWARD_WEIGHTS
    return {
        "e1": -w["e1"] * e1 * e1,
        "e2": -w["e2"] * e2 * e2,
        "u": -w["u"] * u * u,
        "de1": -w["de1"] * de1 * de1,
        "de2": -w["de2"] * de2 * de2,
    }


class LaneKeepingAssistEnv(gym.Env):
    """MATLAB LKA plant as a gymnasium env (`laneshift/LaneKeepingAssist-v0`).

    Observation (float32, 6): [e1, e2, de1, de2, int e1, int e2].
    Action: Discrete(31), index i steers (i - 15) degrees.
    Reward: -(10 e1^2 + 5 e2^2 + 2 u^2 + 5 de1^2 + 5 de2^2) with u the steering applied during the
    step that just ended ("previous" steering from the new sample's point of view) and the errors
    taken at the new sample.
    Episode: terminates when |e1| > 1 m, truncates after `max_steps` (150 = 15 s).
    Reset: e1 ~ U(-0.5, 0.5) m, e2 ~ U(-0.1, 0.1) rad, vy = r = 0, integrals 0; override with
    `reset(options={"e1": -0.4, "e2": 0.2})` or `set_initial_state(e1, e2)`.
    """

    metadata = {"render_modes": []}

    def __init__(
        self,
        max_steps: int = 150,
        curvature: float = 0.001,
        e1_reset: float = 0.5,
        e2_reset: float = 0.1,
        e1_limit: float = 1.0,
        render_mode: str | None = None,
    ) -> None:
        if not isinstance(max_steps, (int, np.integer)) or max_steps < 1:
            raise ValueError(f"max_steps must be a positive int, got {max_steps!r}")
        for name, value in (("e1_reset", e1_reset), ("e2_reset", e2_reset), ("e1_limit", e1_limit)):
            if not np.isfinite(value) or value < 0:
                raise ValueError(f"{name} must be a finite number >= 0, got {value!r}")
        if not np.isfinite(curvature):
            raise ValueError(f"curvature must be finite, got {curvature!r}")
        if render_mode is not None:
            raise ValueError(f"render_mode: LaneKeepingAssist-v0 has no rendering, got {render_mode!r}")
        self.params = LKAParams(rho=float(curvature))
        self.max_steps = int(max_steps)
        self.e1_reset = float(e1_reset)
        self.e2_reset = float(e2_reset)
        self.e1_limit = float(e1_limit)
        self.render_mode = render_mode
        self.Ad, self.Bd, self.Ed = discrete_model(self.params)
        # The disturbance is constant: fold it into one offset vector once.
        self._offset = self.Ed * self.params.rho
        self.action_space = spaces.Discrete(len(LKA_STEERING_DEG))
        self.observation_space = spaces.Box(-np.inf, np.inf, shape=(6,), dtype=np.float32)
        self.state = np.zeros(6)
        self.steps = 0
        self.last_u = 0.0

    # -- helpers -----------------------------------------------------------------------------
    def derivatives(self) -> tuple[float, float]:
        """(de1/dt, de2/dt) at the current state."""
        vy, r, _, e2, _, _ = self.state
        return float(vy + self.params.Vx * e2), float(r - self.params.Vx * self.params.rho)

    def _obs(self) -> np.ndarray:
        de1, de2 = self.derivatives()
        _, _, e1, e2, ie1, ie2 = self.state
        return np.array([e1, e2, de1, de2, ie1, ie2], dtype=np.float32)

    def set_initial_state(self, e1: float, e2: float) -> np.ndarray:
        """Restart the episode from lateral deviation e1 [m] and relative yaw e2 [rad]; returns obs."""
        self.state = np.array([0.0, 0.0, float(e1), float(e2), 0.0, 0.0])
        self.steps = 0
        self.last_u = 0.0
        return self._obs()

    # -- gymnasium API -----------------------------------------------------------------------
    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        super().reset(seed=seed)
        options = options or {}
        unknown = set(options) - {"e1", "e2"}
        if unknown:
            raise ValueError(f"options: unknown keys {sorted(unknown)} (allowed: e1, e2)")
        e1 = options.get("e1")
        e2 = options.get("e2")
        # Draw both so that the random stream does not depend on which option is given.
        r1 = self.np_random.uniform(-self.e1_reset, self.e1_reset)
        r2 = self.np_random.uniform(-self.e2_reset, self.e2_reset)
        obs = self.set_initial_state(r1 if e1 is None else e1, r2 if e2 is None else e2)
        return obs, self._info(0.0, None)

    def step(self, action: int) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        a = int(action)
        if not 0 <= a < len(LKA_STEERING_DEG):
            raise ValueError(f"action must be in [0, {len(LKA_STEERING_DEG)}), got {action!r}")
        u = float(np.clip(LKA_STEERING_RAD[a], -self.params.u_limit, self.params.u_limit))
        self.state = self.Ad @ self.state + self.Bd * u + self._offset
        self.steps += 1
        self.last_u = u
        terms = self._terms(u)
        reward = float(sum(terms.values()))
        e1 = float(self.state[2])
        terminated = bool(abs(e1) > self.e1_limit)
        truncated = bool(self.steps >= self.max_steps and not terminated)
        return self._obs(), reward, terminated, truncated, self._info(u, terms)

    def _terms(self, u: float) -> dict[str, float]:
        de1, de2 = self.derivatives()
        return lka_reward_terms(float(self.state[2]), float(self.state[3]), u, de1, de2)

    def _info(self, u: float, terms: dict[str, float] | None) -> dict[str, Any]:
        e1 = float(self.state[2])
        return {
            "e1": e1,
            "e2": float(self.state[3]),
            "steering": u,
            "crashed": bool(abs(e1) > self.e1_limit),
            "reward_terms": terms if terms is not None else self._terms(u),
            "steps": self.steps,
        }
