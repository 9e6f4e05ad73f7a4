"""A delivery robot's world, stepped in fixed time steps: pure state, seeded randomness.

The robot leaves its depot, loads an order, drives to a dock, delivers, drives back,
charges when its battery is low, and repeats. Frames follow REP-103/105: the odom
frame is aligned with ENU (x east, y north), so GPS, IMU heading and odometry agree.
Faults appear now and then (a motor overcurrent ERROR, a weak-wifi WARN, a lost GPS
fix) so the bridge's handling of them can be seen.
"""

from __future__ import annotations

import math
import random
from dataclasses import dataclass, field

DEPOT = ("depot", 0.0, 0.0)
DOCKS = (("dock-B3", 40.0, 20.0), ("dock-A1", -25.0, 35.0), ("dock-C7", 30.0, -30.0))
ORIGIN_LAT, ORIGIN_LON, ORIGIN_ALT = 41.8781, -87.6298, 182.5
EARTH_RADIUS_M = 6_378_137.0
MAX_SPEED_MPS = 1.0
MAX_YAW_RATE = math.radians(45.0)
WHEEL_RADIUS_M = 0.1
TRACK_WIDTH_M = 0.5
ARRIVE_RADIUS_M = 0.5
ARRIVING_RADIUS_M = 3.0
LOAD_S = 3.0
UNLOAD_S = 3.0
CHARGE_BELOW_PCT = 30.0
CHARGED_PCT = 95.0


@dataclass
class Fault:
    name: str
    level: int  # diagnostic_msgs/DiagnosticStatus level: 1 WARN, 2 ERROR
    message: str
    hardware_id: str
    remaining_s: float


@dataclass
class World:
    """Everything the robot node publishes is read off this state."""

    rng: random.Random
    t: float = 0.0
    x: float = 0.0
    y: float = 0.0
    yaw: float = 0.0
    v: float = 0.0
    yaw_rate: float = 0.0
    cmd_v: float = 0.0
    cmd_yaw_rate: float = 0.0
    accel: float = 0.0
    soc_pct: float = 82.5
    charging: bool = False
    wheel_left_rad: float = 0.0
    wheel_right_rad: float = 0.0
    state: str = "idle"
    state_since: float = 0.0
    order_number: int = 8820
    dock_index: int = -1
    goal: tuple[str, float, float] | None = None
    goal_serial: int = 0
    faults: list[Fault] = field(default_factory=list)
    gps_lost_s: float = 0.0

    @classmethod
    def create(cls, seed: int = 0) -> World:
        return cls(rng=random.Random(seed))

    # ------------------------------------------------------------ derived values

    @property
    def order_id(self) -> str:
        return f"order-{self.order_number}"

    @property
    def package_id(self) -> str:
        return f"pkg-{self.order_number + 680}"

    @property
    def destination(self) -> str:
        return DOCKS[self.dock_index][0] if self.dock_index >= 0 else DEPOT[0]

    @property
    def task_status(self) -> str:
        return {"idle": "none", "charging": "none", "delivered": "completed"}.get(
            self.state, "in_progress"
        )

    @property
    def robot_state(self) -> str:
        return {"idle": "idle", "charging": "charging"}.get(self.state, "autonomous")

    def lat_lon(self) -> tuple[float, float]:
        lat = ORIGIN_LAT + math.degrees(self.y / EARTH_RADIUS_M)
        lon = ORIGIN_LON + math.degrees(
            self.x / (EARTH_RADIUS_M * math.cos(math.radians(ORIGIN_LAT)))
        )
        return lat, lon

    def voltage_v(self) -> float:
        return 21.0 + 4.2 * self.soc_pct / 100.0

    def current_a(self) -> float:
        return 5.0 if self.charging else -(0.8 + 1.5 * abs(self.v))

    # ------------------------------------------------------------ stepping

    def step(self, dt: float) -> None:
        """Advance the world by ``dt`` seconds."""
        self.t += dt
        self._advance_mission()
        self._drive(dt)
        self._update_battery(dt)
        self._update_faults(dt)

    def _set_state(self, state: str) -> None:
        self.state, self.state_since = state, self.t

    def _set_goal(self, goal: tuple[str, float, float]) -> None:
        self.goal = goal
        self.goal_serial += 1

    def _advance_mission(self) -> None:
        in_state = self.t - self.state_since
        if self.state == "idle":
            if self.soc_pct < CHARGE_BELOW_PCT:
                self._set_state("charging")
            else:
                self.order_number += 1
                self.dock_index = (self.dock_index + 1) % len(DOCKS)
                self._set_state("loading")
        elif self.state == "charging":
            self.charging = True
            if self.soc_pct >= CHARGED_PCT:
                self.charging = False
                self._set_state("idle")
        elif self.state == "loading" and in_state >= LOAD_S:
            self._set_goal(DOCKS[self.dock_index])
            self._set_state("in_transit")
        elif self.state in ("in_transit", "arriving"):
            distance = self._distance_to_goal()
            if self.state == "in_transit" and distance < ARRIVING_RADIUS_M:
                self._set_state("arriving")
            elif distance < ARRIVE_RADIUS_M:
                self._set_state("delivered")
        elif self.state == "delivered" and in_state >= UNLOAD_S:
            self._set_goal(DEPOT)
            self._set_state("returning")
        elif self.state == "returning" and self._distance_to_goal() < ARRIVE_RADIUS_M:
            self.goal = None
            self._set_state("idle")

    def _distance_to_goal(self) -> float:
        if self.goal is None:
            return 0.0
        return math.hypot(self.goal[1] - self.x, self.goal[2] - self.y)

    def _drive(self, dt: float) -> None:
        driving = self.state in ("in_transit", "arriving", "returning") and self.goal is not None
        if driving and self.goal is not None:
            bearing = math.atan2(self.goal[2] - self.y, self.goal[1] - self.x)
            error = math.atan2(math.sin(bearing - self.yaw), math.cos(bearing - self.yaw))
            self.cmd_yaw_rate = max(-MAX_YAW_RATE, min(MAX_YAW_RATE, 1.5 * error))
            slow = min(1.0, self._distance_to_goal() / ARRIVING_RADIUS_M)
            self.cmd_v = MAX_SPEED_MPS * slow * max(0.0, math.cos(error))
        else:
            self.cmd_v = self.cmd_yaw_rate = 0.0
        previous_v = self.v
        # the base follows the command with a first-order lag and a little noise
        self.v += (self.cmd_v - self.v) * min(1.0, 4.0 * dt) + self.rng.gauss(0, 0.005) * (
            self.cmd_v > 0
        )
        self.v = max(0.0, self.v)
        self.yaw_rate += (self.cmd_yaw_rate - self.yaw_rate) * min(1.0, 6.0 * dt)
        self.accel = (self.v - previous_v) / dt
        self.yaw = math.atan2(
            math.sin(self.yaw + self.yaw_rate * dt), math.cos(self.yaw + self.yaw_rate * dt)
        )
        self.x += self.v * math.cos(self.yaw) * dt
        self.y += self.v * math.sin(self.yaw) * dt
        left, right = self.wheel_rates()
        self.wheel_left_rad += left * dt
        self.wheel_right_rad += right * dt

    def wheel_rates(self) -> tuple[float, float]:
        left = (self.v - self.yaw_rate * TRACK_WIDTH_M / 2) / WHEEL_RADIUS_M
        right = (self.v + self.yaw_rate * TRACK_WIDTH_M / 2) / WHEEL_RADIUS_M
        return left, right

    def _update_battery(self, dt: float) -> None:
        if self.charging:
            self.soc_pct = min(100.0, self.soc_pct + 0.5 * dt)
        else:
            self.soc_pct = max(0.0, self.soc_pct - (0.01 + 0.04 * self.v) * dt)

    def _update_faults(self, dt: float) -> None:
        for fault in self.faults:
            fault.remaining_s -= dt
        self.faults = [f for f in self.faults if f.remaining_s > 0]
        self.gps_lost_s = max(0.0, self.gps_lost_s - dt)
        if self.rng.random() < 0.004 * dt * 10:
            self.faults.append(
                Fault("motor_controller", 2, "overcurrent on left drive", "mc-left", 0.3)
            )
        if self.rng.random() < 0.01 * dt * 10:
            self.faults.append(Fault("wifi", 1, "weak signal (-78 dBm)", "wlan0", 4.0))
        if self.rng.random() < 0.002 * dt * 10:
            self.gps_lost_s = 2.0

    def scan_ranges(self, beams: int, range_min: float, range_max: float) -> list[float]:
        """A room-like scan with the hostile values real lidars produce: inf beyond
        range, NaN for bad returns, and self-hits below range_min."""
        ranges = []
        for i in range(beams):
            angle = -math.pi + 2 * math.pi * i / beams
            distance = 4.0 + 2.5 * math.sin(3 * angle + 0.2 * self.t) + self.rng.gauss(0, 0.02)
            roll = self.rng.random()
            if roll < 0.03:
                distance = math.inf
            elif roll < 0.04:
                distance = math.nan
            elif roll < 0.05:
                distance = range_min / 2
            ranges.append(min(distance, range_max * 2))
        return ranges
