"""A local controller in the manner of dwa_local_planner, vectorised over all sampled trajectories.

One control cycle (:meth:`DWAController.compute_velocity`), as ``DWAPlanner::findBestPath``:

1. If the robot is within ``xy_goal_tolerance`` of the global goal, the latched stop-and-rotate
   controller takes over (``LatchedStopRotateController``): brake within the acceleration limits,
   then rotate in place to the goal yaw; the goal is reached when the yaw is within
   ``yaw_goal_tolerance`` and the robot has stopped.
2. Otherwise sample ``vx_samples`` x ``vth_samples`` velocities in the dynamic window (current
   velocity +- acceleration limit x ``sim_period`` = 1 / controller_frequency, clipped to the
   velocity limits, zero included when the window spans it), drop those slower than both
   ``min_vel_trans`` and ``min_vel_theta`` or faster than ``max_vel_trans``.
3. Roll every trajectory out for ``sim_time`` at constant velocity (exact unicycle arcs) as one
   (n_samples x n_steps) array, with steps no longer than ``sim_granularity`` /
   ``angular_sim_granularity``.
4. Score them all at once; lower is better (``DWAPlanner::updatePlanAndLocalCosts`` weights)::

       0.5 path_distance_bias (d_plan(end) + d_plan(nose))
     + 0.5 goal_distance_bias (d_goal(end) + d_goal_front(nose))
     + occdist_scale * max (``sum_scores``: sum) of the costs along the trajectory
     + twirling_scale * |w|

   with ``nose`` the point ``forward_point_distance`` ahead of the trajectory's end, distances in
   metres to the local plan (the part of the global plan inside the local costmap) and to its
   last point. The nose term on the plan is dropped close to the goal, as DWA does. Trajectories
   that touch a cell of cost >= 253 (inscribed or lethal), unknown space or leave the local
   costmap are rejected, and so are rotations/translations forbidden by the oscillation flags
   (``OscillationCostFunction``).
5. No valid trajectory -> failure (move_base then replans and, after ``controller_patience``,
   runs its recoveries).

Differences from DWA (documented): distances to the plan and goal are Euclidean instead of the
map grid's obstacle-aware wavefront; the circular footprint is checked at its centre against the
inflated costs (exact for a circular robot) and is not scaled with speed.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional, Tuple

import numpy as np

from cnr_navigation.core.costmap import INSCRIBED_INFLATED_OBSTACLE, NO_INFORMATION, LayeredCostmap
from cnr_navigation.core.geometry import IDENTITY, Pose2D, normalize_angle, transform_path

Velocity = Tuple[float, float]


@dataclass
class DWAConfig:
    """``~DWAPlannerROS/*`` (DWAPlanner.cfg and local_planner_limits; units m, rad, s)."""

    max_vel_trans: float
    min_vel_trans: float
    max_vel_x: float
    min_vel_x: float
    max_vel_y: float
    min_vel_y: float
    max_vel_theta: float
    min_vel_theta: float
    acc_lim_x: float
    acc_lim_y: float
    acc_lim_theta: float
    acc_lim_trans: float
    prune_plan: bool
    xy_goal_tolerance: float
    yaw_goal_tolerance: float
    trans_stopped_vel: float
    theta_stopped_vel: float
    sim_time: float
    sim_granularity: float
    angular_sim_granularity: float
    path_distance_bias: float
    goal_distance_bias: float
    occdist_scale: float
    twirling_scale: float
    stop_time_buffer: float
    oscillation_reset_dist: float
    oscillation_reset_angle: float
    forward_point_distance: float
    scaling_speed: float
    max_scaling_factor: float
    vx_samples: int
    vy_samples: int
    vth_samples: int
    use_dwa: bool
    latch_xy_goal_tolerance: bool
    cheat_factor: float
    sum_scores: bool


@dataclass
class ControlResult:
    """Outcome of one control cycle.

    Attributes:
        cmd: (v [m/s], w [rad/s]) to send, or None when no valid command exists.
        trajectory: (K, 3) poses of the chosen trajectory in the local frame (empty when rotating
            or stopping at the goal).
        mode: 'dwa', 'stop', 'rotate', 'goal' or 'failed'.
        n_valid: number of collision-free sampled trajectories.
    """

    cmd: Optional[Velocity]
    trajectory: np.ndarray
    mode: str
    n_valid: int = 0


def velocity_samples(lo: float, hi: float, n: int) -> np.ndarray:
    """``n`` evenly spaced samples in [lo, hi], plus 0 if the interval spans it (VelocityIterator)."""
    if hi < lo:
        hi = lo
    n = max(1, int(n))
    samples = np.array([lo]) if n == 1 or hi == lo else np.linspace(lo, hi, n)
    if lo < 0.0 < hi and not np.any(samples == 0.0):
        samples = np.sort(np.append(samples, 0.0))
    return samples


def rollout(pose: Pose2D, v: np.ndarray, w: np.ndarray, sim_time: float, n_steps: int) -> np.ndarray:
    """Unicycle trajectories at constant (v, w) [m/s, rad/s] for ``sim_time`` [s].

    Returns:
        (n_samples, n_steps, 3) array of (x, y, yaw) at t = k sim_time / n_steps, k = 1..n_steps.
    """
    t = np.arange(1, n_steps + 1) * (sim_time / n_steps)
    v = np.asarray(v, dtype=np.float64)[:, None]
    w = np.asarray(w, dtype=np.float64)[:, None]
    theta = pose.yaw + w * t[None, :]
    straight = np.abs(w) < 1e-6
    w_safe = np.where(straight, 1.0, w)
    x_arc = pose.x + v / w_safe * (np.sin(theta) - math.sin(pose.yaw))
    y_arc = pose.y - v / w_safe * (np.cos(theta) - math.cos(pose.yaw))
    x_lin = pose.x + v * t[None, :] * math.cos(pose.yaw)
    y_lin = pose.y + v * t[None, :] * math.sin(pose.yaw)
    x = np.where(straight, x_lin, x_arc)
    y = np.where(straight, y_lin, y_arc)
    return np.stack((x, y, theta), axis=-1)


def point_to_points_distance(px: np.ndarray, py: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """Distance [m] from each point to the nearest of ``targets`` ((M, >=2) array)."""
    if targets.shape[0] == 0:
        return np.zeros(px.shape)
    dx = px[..., None] - targets[:, 0]
    dy = py[..., None] - targets[:, 1]
    return np.sqrt((dx * dx + dy * dy).min(axis=-1))


class DWAController:
    """Vectorised DWA-style local controller; see the module docstring.

    Args:
        cfg: planner parameters.
        controller_frequency: move_base's control rate [Hz]; sim_period = 1 / frequency.
    """

    def __init__(self, cfg: DWAConfig, controller_frequency: float) -> None:
        self.cfg = cfg
        self.sim_period = 1.0 / controller_frequency if controller_frequency > 0 else 0.05
        self.plan = np.zeros((0, 3))
        self._latched = False
        self._rotating = False
        self._osc = dict(fwd_pos=False, fwd_neg=False, rot_pos=False, rot_neg=False,
                         fwd_pos_only=False, fwd_neg_only=False, rot_pos_only=False, rot_neg_only=False)
        self._osc_origin: Optional[Pose2D] = None

    # -- configuration ---------------------------------------------------------------------------
    def set_controller_frequency(self, frequency: float) -> None:
        self.sim_period = 1.0 / frequency if frequency > 0 else 0.05

    def set_plan(self, plan: np.ndarray) -> bool:
        """Take a new global plan ((N, 3) in the global frame); False if it is empty."""
        plan = np.asarray(plan, dtype=np.float64).reshape(-1, 3)
        if plan.shape[0] == 0:
            return False
        goal_changed = self.plan.shape[0] == 0 or not np.allclose(self.plan[-1], plan[-1])
        self.plan = plan
        if goal_changed:
            self._latched = False
            self._rotating = False
        self._reset_oscillation()
        return True

    def reset(self) -> None:
        self.plan = np.zeros((0, 3))
        self._latched = False
        self._rotating = False
        self._reset_oscillation()

    # -- goal checks -----------------------------------------------------------------------------
    def _goal_local(self, global_to_local: Pose2D) -> Optional[np.ndarray]:
        if self.plan.shape[0] == 0:
            return None
        return transform_path(self.plan[-1:], global_to_local)[0]

    def is_position_reached(self, pose: Pose2D, global_to_local: Pose2D = IDENTITY) -> bool:
        goal = self._goal_local(global_to_local)
        if goal is None:
            return False
        return self._latched or math.hypot(goal[0] - pose.x, goal[1] - pose.y) <= self.cfg.xy_goal_tolerance

    def stopped(self, velocity: Velocity) -> bool:
        return abs(velocity[0]) <= self.cfg.trans_stopped_vel and abs(velocity[1]) <= self.cfg.theta_stopped_vel

    def is_goal_reached(self, pose: Pose2D, velocity: Velocity, global_to_local: Pose2D = IDENTITY) -> bool:
        """Position within (or latched at) xy tolerance, yaw within tolerance, robot stopped."""
        goal = self._goal_local(global_to_local)
        if goal is None or not self.is_position_reached(pose, global_to_local):
            return False
        yaw_err = abs(float(normalize_angle(goal[2] - pose.yaw)))
        return yaw_err <= self.cfg.yaw_goal_tolerance and self.stopped(velocity)

    # -- main entry ------------------------------------------------------------------------------
    def compute_velocity(self, pose: Pose2D, velocity: Velocity, costmap: LayeredCostmap,
                         global_to_local: Pose2D = IDENTITY) -> ControlResult:
        """One control cycle.

        Args:
            pose: robot pose in the local costmap's frame.
            velocity: current (v, w) of the base [m/s, rad/s] (from odometry).
            costmap: the local costmap.
            global_to_local: pose of the global (plan) frame in the local frame.
        """
        empty = np.zeros((0, 3))
        if self.plan.shape[0] == 0:
            return ControlResult(None, empty, 'failed')
        goal = self._goal_local(global_to_local)
        assert goal is not None
        if self.is_position_reached(pose, global_to_local):
            if self.cfg.latch_xy_goal_tolerance:
                self._latched = True
            return self._stop_and_rotate(pose, velocity, costmap, float(goal[2]))
        self._rotating = False
        return self._dwa(pose, velocity, costmap, global_to_local)

    # -- near the goal: LatchedStopRotateController -------------------------------------------------
    def _footprint_ok(self, costmap: LayeredCostmap, x: float, y: float) -> bool:
        cost = int(costmap.cost_at(x, y))
        return cost < INSCRIBED_INFLATED_OBSTACLE

    def _stop_and_rotate(self, pose: Pose2D, velocity: Velocity, costmap: LayeredCostmap,
                         goal_yaw: float) -> ControlResult:
        c = self.cfg
        empty = np.zeros((0, 3))
        ang = float(normalize_angle(goal_yaw - pose.yaw))
        if abs(ang) <= c.yaw_goal_tolerance:
            self._rotating = False
            return ControlResult((0.0, 0.0), empty, 'goal')
        v, w = velocity
        if not self._rotating and not self.stopped(velocity):
            vx = math.copysign(max(0.0, abs(v) - c.acc_lim_x * self.sim_period), v)
            vth = math.copysign(max(0.0, abs(w) - c.acc_lim_theta * self.sim_period), w)
            if not self._footprint_ok(costmap, pose.x + vx * self.sim_period * math.cos(pose.yaw),
                                      pose.y + vx * self.sim_period * math.sin(pose.yaw)):
                return ControlResult(None, empty, 'failed')
            return ControlResult((vx, vth), empty, 'stop')
        self._rotating = True
        vth = min(c.max_vel_theta, max(c.min_vel_theta, abs(ang)))
        max_acc_vel = abs(w) + c.acc_lim_theta * self.sim_period
        min_acc_vel = abs(w) - c.acc_lim_theta * self.sim_period
        vth = min(max(abs(vth), min_acc_vel), max_acc_vel)
        vth = min(math.sqrt(2.0 * c.acc_lim_theta * abs(ang)), vth)
        vth = min(c.max_vel_theta, max(c.min_vel_theta, vth))
        if ang < 0:
            vth = -vth
        if not self._footprint_ok(costmap, pose.x, pose.y):
            return ControlResult(None, empty, 'failed')
        return ControlResult((0.0, vth), empty, 'rotate')

    # -- the dynamic window --------------------------------------------------------------------------
    def sample_velocities(self, velocity: Velocity) -> Tuple[np.ndarray, np.ndarray]:
        """The (v, w) pairs to simulate, as two flat arrays."""
        c = self.cfg
        v0, w0 = velocity
        dt = self.sim_period if c.use_dwa else c.sim_time
        v_lo, v_hi = max(c.min_vel_x, v0 - c.acc_lim_x * dt), min(c.max_vel_x, v0 + c.acc_lim_x * dt)
        w_lo = max(-c.max_vel_theta, w0 - c.acc_lim_theta * dt)
        w_hi = min(c.max_vel_theta, w0 + c.acc_lim_theta * dt)
        vs = velocity_samples(v_lo, v_hi, c.vx_samples)
        ws = velocity_samples(w_lo, w_hi, c.vth_samples)
        vv, ww = np.meshgrid(vs, ws, indexing='ij')
        vv, ww = vv.ravel(), ww.ravel()
        eps = 1e-5
        ok = ~((np.abs(vv) + eps < c.min_vel_trans) & (np.abs(ww) + eps < c.min_vel_theta))
        ok &= np.abs(vv) - eps <= c.max_vel_trans
        return vv[ok], ww[ok]

    def local_plan(self, pose: Pose2D, costmap: LayeredCostmap, global_to_local: Pose2D) -> np.ndarray:
        """The global plan in the local frame, from its point nearest the robot to where it leaves
        the local costmap (``transformGlobalPlan``; with ``prune_plan``, points behind are dropped)."""
        plan = transform_path(self.plan, global_to_local)
        g = costmap.geometry
        dist_threshold = max(g.width, g.height) * g.resolution / 2.0
        d = np.hypot(plan[:, 0] - pose.x, plan[:, 1] - pose.y)
        near = np.flatnonzero(d <= (min(1.0, dist_threshold) if self.cfg.prune_plan else dist_threshold))
        if near.size == 0:
            return plan[:0]
        start = int(near[0])
        beyond = np.flatnonzero(d[start:] > dist_threshold)
        end = start + int(beyond[0]) if beyond.size else plan.shape[0]
        return plan[start:end]

    def _dwa(self, pose: Pose2D, velocity: Velocity, costmap: LayeredCostmap,
             global_to_local: Pose2D) -> ControlResult:
        c = self.cfg
        empty = np.zeros((0, 3))
        self._update_oscillation_reset(pose)
        vv, ww = self.sample_velocities(velocity)
        if vv.size == 0:
            return ControlResult(None, empty, 'failed')
        n_steps = int(math.ceil(max(c.sim_time * float(np.abs(vv).max()) / c.sim_granularity,
                                    c.sim_time * float(np.abs(ww).max()) / c.angular_sim_granularity, 1.0)))
        traj = rollout(pose, vv, ww, c.sim_time, n_steps)              # (S, K, 3)
        costs = costmap.cost_at(traj[..., 0], traj[..., 1], outside=NO_INFORMATION)
        collide = (costs >= INSCRIBED_INFLATED_OBSTACLE).any(axis=1)
        occ = (costs.sum(axis=1) if c.sum_scores else costs.max(axis=1)).astype(np.float64)

        plan = self.local_plan(pose, costmap, global_to_local)
        if plan.shape[0] == 0:      # DWA: "Could not get local plan"
            return ControlResult(None, empty, 'failed')
        local_goal = plan[-1]
        end_x, end_y, end_th = traj[:, -1, 0], traj[:, -1, 1], traj[:, -1, 2]
        nose_x = end_x + c.forward_point_distance * np.cos(end_th)
        nose_y = end_y + c.forward_point_distance * np.sin(end_th)
        d_path_end = point_to_points_distance(end_x, end_y, plan)
        d_path_nose = point_to_points_distance(nose_x, nose_y, plan)
        d_goal_end = np.hypot(end_x - local_goal[0], end_y - local_goal[1])
        angle_to_goal = math.atan2(local_goal[1] - pose.y, local_goal[0] - pose.x)
        front_x = local_goal[0] + c.forward_point_distance * math.cos(angle_to_goal)
        front_y = local_goal[1] + c.forward_point_distance * math.sin(angle_to_goal)
        d_goal_nose = np.hypot(nose_x - front_x, nose_y - front_y)
        goal = self._goal_local(global_to_local)
        assert goal is not None
        sq_dist = (pose.x - goal[0]) ** 2 + (pose.y - goal[1]) ** 2
        align_scale = c.path_distance_bias if sq_dist > (c.forward_point_distance ** 2) * c.cheat_factor else 0.0
        score = 0.5 * c.path_distance_bias * d_path_end + 0.5 * align_scale * d_path_nose \
            + 0.5 * c.goal_distance_bias * (d_goal_end + d_goal_nose) \
            + c.occdist_scale * occ + c.twirling_scale * np.abs(ww)
        valid = ~collide & self._oscillation_ok(vv, ww)
        n_valid = int(valid.sum())
        if n_valid == 0:
            return ControlResult(None, empty, 'failed', 0)
        score = np.where(valid, score, np.inf)
        best = int(np.argmin(score))
        v_best, w_best = float(vv[best]), float(ww[best])
        self._set_oscillation_flags(pose, v_best, w_best)
        return ControlResult((v_best, w_best), traj[best], 'dwa', n_valid)

    # -- oscillation flags (base_local_planner::OscillationCostFunction) ------------------------------
    def _reset_oscillation(self) -> None:
        for key in self._osc:
            self._osc[key] = False
        self._osc_origin = None

    def _update_oscillation_reset(self, pose: Pose2D) -> None:
        o = self._osc_origin
        if o is None:
            return
        if pose.distance(o) > self.cfg.oscillation_reset_dist or \
                abs(float(normalize_angle(pose.yaw - o.yaw))) > self.cfg.oscillation_reset_angle:
            self._reset_oscillation()

    def _oscillation_ok(self, vv: np.ndarray, ww: np.ndarray) -> np.ndarray:
        f = self._osc
        bad = np.zeros(vv.shape, dtype=bool)
        if f['fwd_pos_only']:
            bad |= vv < 0.0
        if f['fwd_neg_only']:
            bad |= vv > 0.0
        if f['rot_pos_only']:
            bad |= ww < 0.0
        if f['rot_neg_only']:
            bad |= ww > 0.0
        return ~bad

    def _set_oscillation_flags(self, pose: Pose2D, v: float, w: float) -> None:
        f = self._osc
        flag_set = False
        if v < 0.0:
            if f['fwd_pos']:
                f['fwd_neg_only'] = flag_set = True
            f['fwd_pos'], f['fwd_neg'] = False, True
        if v > 0.0:
            if f['fwd_neg']:
                f['fwd_pos_only'] = flag_set = True
            f['fwd_neg'], f['fwd_pos'] = False, True
        if abs(v) <= self.cfg.min_vel_trans:
            if w < 0.0:
                if f['rot_pos']:
                    f['rot_neg_only'] = flag_set = True
                f['rot_pos'], f['rot_neg'] = False, True
            if w > 0.0:
                if f['rot_neg']:
                    f['rot_pos_only'] = flag_set = True
                f['rot_neg'], f['rot_pos'] = False, True
        if flag_set:
            self._osc_origin = pose
