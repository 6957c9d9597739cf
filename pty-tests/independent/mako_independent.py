#!/usr/bin/env python3
"""An independent Mako AUV and EyeBot sensor model that writes `gap` measurement directories.

It shares no code, equations or parameter files with eyebot-hil's simulator (`src/physics`,
`src/sensors`): a planar surge/sway/yaw manoeuvring model plus separate heave, pitch and roll,
its own damping laws, thruster model, sensors, discretisation and noise. An EyeBot-style
closed-loop program drives it on its *measured* sensors; the run is written in the documented
format (`docs/gap.md`, "A measurement") plus `truth.json`, which `gap` never reads.

Frames (the project's conventions): world NED, origin at a surface corner of the 25 x 12.5 x
2 m pool, x north, y east, z down; body x forward, y starboard, z down; yaw = heading,
degrees clockwise from north. Standard library only; deterministic for given arguments.

Run `python3 mako_independent.py --list`; README.md next to this file explains the model.
"""

import argparse
import json
import math
import os
import random
import sys
import time

VERSION = "mako-independent 1"
DT_S = 0.005  # s, physics step (semi-implicit Euler)
TICKS_PER_S = 200  # all timing runs on integer ticks of DT_S

# ---------------------------------------------------------------------------------------------
# Nominal ("true") parameters of this model. Calibrated to thesis 4.5-4.7 (top speed 0.44 m/s,
# ~6 s to reach it, ~32 s coast-down, spot turn ~0.8 m circle in ~23 s), chosen independently
# of configs/vehicles/mako.toml; README.md lists how they compare.
# ---------------------------------------------------------------------------------------------
NOMINAL = {
    # rigid body + added mass (kg, kg m^2)
    "mass_kg": 35.0,
    "m_surge_kg": 39.5,          # 35 + 4.5 added
    "m_sway_kg": 63.0,           # 35 + 28 added
    "m_heave_kg": 66.0,          # 35 + 31 added
    "i_yaw_kgm2": 6.3,           # 3.9 rigid + 2.4 added
    "i_pitch_kgm2": 6.8,
    "i_roll_kgm2": 1.6,
    # surge resistance R(u) = a u + b u|u| + c u^3 (N)
    "surge_lin": 4.2, "surge_quad": 1.0, "surge_cubic": 14.6,
    # sway resistance a v + b v|v| (N); yaw (a + a_u |u|) r + b r|r| (N m): the hull's lift
    # adds yaw damping in proportion to the forward speed
    "sway_lin": 55.0, "sway_quad": 120.0,
    "yaw_lin": 2.05, "yaw_lin_per_speed": 4.0, "yaw_quad": 1.6,
    # sway-yaw cross damping: Y = -Y_r r (N per rad/s), N = -(N_v + N_vu u) v (N m per m/s);
    # N_vu < 0: the lateral force centre lies aft, which keeps Mako straight against the Munk
    # moment (m_sway - m_surge) u v
    "y_r": -0.3, "n_v": 2.0, "n_v_per_speed": -12.0,
    # heave a w + b w|w| (N); extra wave-making damping while the hull breaks the surface
    "heave_lin": 6.0, "heave_quad": 70.0, "surface_damping": 120.0,
    "pitch_lin": 6.0, "pitch_quad": 4.0, "roll_lin": 1.5, "roll_quad": 1.0,
    # hydrostatics
    "reserve_buoyancy_n": 1.47,  # N, buoyancy minus weight when submerged
    "top_above_com_m": 0.24,     # m, top of the upper hull above the centre of mass
    "bottom_below_com_m": 0.22,  # m
    "waterplane_m2": 0.09,       # m^2, area cut by the surface while the top emerges
    "righting_pitch_nm": 12.0,   # N m per rad (W * BG * sin)
    "righting_roll_nm": 12.0,
    # thrusters: rpm fraction n follows n_ss = sign(c) ((|c|-db)/(1-db))^k with first-order lag,
    # thrust = K n|n| (K_rev in reverse)
    "thrust_fwd_n": 1.68,        # N at full forward, per motor (gain 1)
    "reverse_ratio": 0.52,
    "deadband": 0.08,            # fraction of full command below which the propeller stands
    "rpm_exponent": 0.65,
    "tau_spin_up_s": 0.35,
    "tau_spin_down_s": 0.6,
    "gains": [1.0, 0.96, 1.0, 0.97],  # port, starboard, bow, stern (equal commands turn right)
    "lever_horizontal_m": 0.29,  # m, port/starboard thrust line from the centre line
    "lever_vertical_m": 0.55,    # m, bow/stern thrusters from the centre of mass
    "thrust_line_above_com_m": 0.04,
    "rpm_fluctuation_rel": 0.04, "rpm_fluctuation_tau_s": 0.5,
    # coloured process noise (Ornstein-Uhlenbeck, 1 sigma, correlation time)
    "dist_surge_n": 0.03, "dist_sway_n": 0.06, "dist_yaw_nm": 0.015, "dist_heave_n": 0.04,
    "dist_tau_s": 2.0,
    # pool contact (hull corners against the walls)
    "wall_stiffness_npm": 400.0, "wall_damping_nspm": 60.0,
}

SENSORS = {
    "adc_ref_v": 5.0, "adc_codes": 1024, "adc_board_noise_v": 0.003,
    # depth: gauge pressure at the sensor port, amplifier 1 V/m (true gain and offset below)
    "depth_port_body_m": [-0.47, 0.0, 0.13],
    "depth_gain_v_per_m": 1.012, "depth_offset_v": 0.006,
    "depth_tau_s": 0.023, "depth_noise_v": 0.0015, "depth_emi_v_full_duty": 0.004,
    # accelerometer (MMA7260Q) at the EyeBot, with its own zero-g, sensitivity and mounting
    "accel_body_m": [0.10, 0.0, -0.12],
    "accel_zero_g_v": [1.662, 1.641, 1.671], "accel_v_per_g": [0.79, 0.81, 0.805],
    "accel_noise_v": 0.0047, "accel_vibration_g": 0.01, "accel_misalign_deg": [0.8, 1.2],
    # paddle wheel (Navman Speed 2100) under the lower hull
    "paddle_pulses_per_m": 20.0, "paddle_slip": 0.93, "paddle_stall_mps": 0.015,
    "paddle_tau_s": 0.4, "firmware_m_per_pulse": 0.25, "window_s": 1.0, "poll_s": 0.01,
    # Vector 2X compass: Earth field at Perth, what calibration left, conversion timing
    "field_ut": 58.0, "inclination_deg": -66.0, "declination_deg": -1.0,
    "residual_hard_iron_ut": [0.5, -0.35], "soft_iron": [[1.015, 0.008], [0.008, 0.985]],
    "compass_noise_ut": 0.25, "compass_period_s": 0.4, "compass_xy_gap_s": 0.05,
    "compass_ready_s": 0.13,
    # overhead camera tracking a marker on the upper hull
    "camera_marker_body_m": [0.05, 0.0], "camera_period_s": 0.2, "camera_std_m": 0.015,
    "camera_dropout": 0.02,
    # sonar (Navman 2100 transducers via the PICAXE multiplexer), 2008 mounting
    "sonar_mount": [  # name, body x, body y, azimuth deg (+ starboard)
        ["port-fore", 0.25, -0.32, -75.0], ["port-aft", -0.25, -0.32, -105.0],
        ["bow-port", 0.67, -0.10, -15.0], ["bow-starboard", 0.67, 0.10, 15.0]],
    "sonar_half_beam_deg": 5.0, "sonar_max_incidence_deg": 20.0, "sonar_incidence_sigma_deg": 12.0,
    "sonar_range_half_m": 3.72, "sonar_range_width_m": 0.07, "sonar_min_range_m": 0.3,
    "sonar_speed_half_mps": 0.35, "sonar_noise_m": 0.03, "sonar_resolution_m": 0.1,
    "sonar_period_s": 1.0, "sonar_latency_s": 0.1,
}

POOL = {"length_m": 25.0, "width_m": 12.5, "depth_m": 2.0, "rho": 998.2, "g": 9.794}

# name -> (default size, unit, meaning)
EFFECTS = {
    "none": (None, "", "nothing hidden: a null run"),
    "water_current": ([0.02, -0.015], "m/s north, east", "steady current in the pool"),
    "compass_hard_iron": ([3.0, 2.0], "uT body x, y", "extra magnetic offset on the hull: heading error once per turn"),
    "compass_latency": (0.4, "s", "extra delay before a compass reading reaches the program"),
    "compass_offset": (6.0, "deg", "compass mounted rotated: constant heading offset"),
    "thruster_imbalance": (0.08, "differential gain", "port x (1 + g/2), starboard x (1 - g/2)"),
    "depth_emi": (0.03, "V rms at the ADC at 100 % stern duty", "stern PWM noise on the depth channel, linear in duty"),
    "depth_offset": (0.08, "m", "depth channel zero offset (metres of water)"),
    "depth_gain": (0.10, "relative", "depth channel gain error: volts per metre x (1 + size)"),
    "accel_offset": ([0.03, -0.03, 0.0], "V on x, y, z", "accelerometer zero-g offsets"),
    "velocity_sensor_scale": (0.25, "relative", "paddle speed x (1 + size)"),
    "thrust_gain": (-0.20, "relative", "all four thrusters x (1 + size)"),
    "thruster_lag": (0.8, "s", "added to both spin-up and spin-down time constants"),
    "drag": (1.35, "scale", "surge and sway resistance x size"),
    "yaw_damping": (1.5, "scale", "yaw damping (linear and quadratic) x size"),
    "sway_yaw_coupling": (5.0, "N m per m/s", "added to N_v, the yaw moment per unit sway speed"),
}

PROGRAMS = {
    "heading_hold": "compass heading hold on out-and-back legs with heading steps and speed changes",
    "spins": "spot turns both ways (100 % and 60 %), turns counted on the compass",
    "depth_hold": "depth hold on the depth ADC with depth steps (bow and stern), heading held",
    "square": "square courses: timed legs, 90 deg turns by compass, both directions",
    "wall_run": "keeps 1.0 m off the wall on the port side by sonar, turns right at corners",
    "mixed": "dive, heading legs at depth, a spin each way, a square: a calibration run",
}


# ---------------------------------------------------------------------------------------------
# The structure family (--structure-seed N): what is drawn, its range, and why. U(a, b) is
# uniform; "p 0.5" is the chance a term is present. Every part has its own random stream
# (`structure/N/part`), apart from the noise seed. `draw_structure` implements this table.
# ---------------------------------------------------------------------------------------------
STRUCTURE_FAMILY = [
    ("mass", "rigid mass U(33.5, 36.5) kg; added mass surge U(2, 8), sway U(20, 36), heave "
     "U(22, 40) kg; yaw, pitch, roll inertia x U(0.8, 1.25)",
     "Mako is weighed (35 kg) but its added mass is only estimated"),
    ("thrust", "full forward thrust U(1.4, 2.0) N per motor; gain per motor U(0.92, 1.04); "
     "reverse/forward ratio U(0.40, 0.70)",
     "hobby thrusters differ from motor to motor and run less well in reverse"),
    ("thruster map", "per motor: dead band U(3, 14) % of full command; saturation (rpm full "
     "from) 100 % (p 0.5) or U(85, 98) %; rpm = x^k, forward k U(0.5, 0.9) and reverse k "
     "U(0.5, 1.0) (each x U(0.95, 1.05) per motor); spin-up lag U(0.2, 0.6) s, spin-down "
     "U(0.35, 0.9) s; thrust ~ rpm|rpm|",
     "the map from PWM to thrust is never linear and never the same forward and back"),
    ("surge drag", "law drawn from linear+quadratic, quadratic, linear+quadratic+cubic, "
     "linear+cubic, quadratic+cubic with weights U(0.2, 1.0), scaled so that 100/100 % runs "
     "at a top speed of 0.44 m/s x U(0.8, 1.2); surge drag growing with sway X = -c u|v|, c "
     "U(5, 30) N s^2/m^2 (p 0.5)",
     "the thesis measured 0.44 m/s; the law's form is what a calibrated model cannot know"),
    ("sway drag", "55 v x U(0.7, 1.4) + 120 v|v| x U(0.6, 1.6), + c v^3 with c U(100, 600) "
     "(p 0.5)", "the hull's cross-flow drag is not measured"),
    ("yaw damping", "(2.05 x U(0.75, 1.3) + 4.0 x U(0, 1.5) |u|) r + 1.6 x U(0.6, 1.6) r|r|, "
     "+ c r^3 with c U(0.5, 3) (p 0.5)",
     "yaw damping was only inferred from spot-turn times; the lift term's size is a guess"),
    ("couplings", "Munk moment on (p 0.7) or off; sway-yaw cross damping Y_r and N_v each off "
     "(p 1/3), positive or negative, |Y_r| U(0.1, 0.6), |N_v| U(0.5, 3); N_vu -12 x U(0.6, 1.4) "
     "with the Munk moment, -12 x U(0, 0.8) without",
     "the surge-sway-yaw coupling of a two-hull vehicle is not known even in sign"),
    ("heave, pitch, roll", "heave 6 w x U(0.6, 1.6) + 70 w|w| x U(0.7, 1.4); surface damping "
     "U(80, 160) N s/m; pitch and roll damping x U(0.7, 1.4); righting moments 12 N m/rad x "
     "U(0.7, 1.4)", "vertical dynamics are only seen through the depth channel"),
    ("buoyancy", "reserve buoyancy U(1.0, 2.0) N; top of the hull U(0.21, 0.27) m and bottom "
     "U(0.19, 0.25) m from the CG; waterplane 0.09 m^2 x U(0.8, 1.2); centre of buoyancy "
     "U(-2, 2) mm ahead of and U(-1, 1) mm to starboard of the CG (a trim at rest, "
     "`--check-family`); thrust line U(0.01, 0.07) m above the CG; thruster levers x U(0.93, 1.07) "
     "sideways, x U(0.9, 1.1) fore-aft",
     "it floats at rest (reserve buoyancy > 0) with the CG at a depth the user does not know"),
    ("sensor placement", "depth port at x U(-0.60, -0.35), y U(-0.05, 0.05), z U(0.05, 0.20) "
     "m; accelerometer at x U(0.0, 0.2) m (the model's specific force uses x only); camera "
     "marker at x U(-0.05, 0.15), y U(-0.04, 0.04) m",
     "lever arms are measured with a ruler, if at all"),
    ("initial state", "per run (structure seed and seed): true start = stated start + an "
     "offset, horizontal U(0, 0.3) m (uniform in a disc), heading U(-20, 20) deg; the CG "
     "starts U(-0.03, 0.26) m below its own float depth (released under water or bobbing); "
     "experiment.toml states the nominal start at the nominal float depth, truth.json the "
     "true one", "a user writes down where the vehicle was meant to start"),
    ("program", "`--program random`, per run (structure seed, if any, and seed): one of the "
     "programs above, uniformly", "closed-loop data of several kinds"),
]

SURGE_LAWS = [("linear", "quadratic"), ("quadratic",), ("linear", "quadratic", "cubic"),
              ("linear", "cubic"), ("quadratic", "cubic")]
START_OFFSET_LIMITS = (0.3, 0.3, 20.0)  # m horizontal, m depth, deg heading


def draw_structure(n):
    """The vehicle (parameters, sensor placement) that structure seed `n` draws from
    STRUCTURE_FAMILY, and a description of its discrete choices."""
    def part(name):
        return random.Random(f"structure/{n}/{name}")

    def on(r, chance, lo, hi):
        """A term present with probability `chance`, then U(lo, hi); else 0."""
        return r.uniform(lo, hi) if r.random() < chance else 0.0

    p = json.loads(json.dumps(NOMINAL))
    sp = json.loads(json.dumps(SENSORS))
    r = part("mass")
    p["mass_kg"] = r.uniform(33.5, 36.5)
    p["m_surge_kg"] = p["mass_kg"] + r.uniform(2.0, 8.0)
    p["m_sway_kg"] = p["mass_kg"] + r.uniform(20.0, 36.0)
    p["m_heave_kg"] = p["mass_kg"] + r.uniform(22.0, 40.0)
    for k in ("i_yaw_kgm2", "i_pitch_kgm2", "i_roll_kgm2"):
        p[k] *= r.uniform(0.8, 1.25)
    r = part("thrust")
    p["thrust_fwd_n"] = r.uniform(1.4, 2.0)
    p["gains"] = [r.uniform(0.92, 1.04) for _ in range(4)]
    p["reverse_ratio"] = r.uniform(0.40, 0.70)
    r = part("thruster map")
    k_fwd, k_rev = r.uniform(0.5, 0.9), r.uniform(0.5, 1.0)
    p["thruster_maps"] = [{
        "deadband": r.uniform(0.03, 0.14),
        "saturation": 1.0 if r.random() < 0.5 else r.uniform(0.85, 0.98),
        "exponent_forward": k_fwd * r.uniform(0.95, 1.05),
        "exponent_reverse": k_rev * r.uniform(0.95, 1.05),
        "tau_spin_up_s": r.uniform(0.2, 0.6),
        "tau_spin_down_s": r.uniform(0.35, 0.9)} for _ in range(4)]
    for k in ("deadband", "rpm_exponent", "tau_spin_up_s", "tau_spin_down_s"):
        del p[k]  # the maps above replace the nominal's single map
    r = part("surge drag")
    top_mps = 0.44 * r.uniform(0.8, 1.2)
    law = r.choice(SURGE_LAWS)
    w = {term: r.uniform(0.2, 1.0) for term in law}
    full_n = p["thrust_fwd_n"] * (p["gains"][0] + p["gains"][1])  # both stern motors at 100 %
    scale = full_n / sum(w.values())
    p["surge_lin"] = scale * w.get("linear", 0.0) / top_mps
    p["surge_quad"] = scale * w.get("quadratic", 0.0) / top_mps ** 2
    p["surge_cubic"] = scale * w.get("cubic", 0.0) / top_mps ** 3
    p["surge_per_sway"] = on(r, 0.5, 5.0, 30.0)
    r = part("sway drag")
    p["sway_lin"] *= r.uniform(0.7, 1.4)
    p["sway_quad"] *= r.uniform(0.6, 1.6)
    p["sway_cubic"] = on(r, 0.5, 100.0, 600.0)
    r = part("yaw damping")
    p["yaw_lin"] *= r.uniform(0.75, 1.3)
    p["yaw_lin_per_speed"] *= r.uniform(0.0, 1.5)
    p["yaw_quad"] *= r.uniform(0.6, 1.6)
    p["yaw_cubic"] = on(r, 0.5, 0.5, 3.0)
    r = part("couplings")
    p["munk_factor"] = 1.0 if r.random() < 0.7 else 0.0
    p["y_r"] = r.choice([0.0, -1.0, 1.0]) * r.uniform(0.1, 0.6)
    p["n_v"] = r.choice([0.0, -1.0, 1.0]) * r.uniform(0.5, 3.0)
    p["n_v_per_speed"] *= r.uniform(0.6, 1.4) if p["munk_factor"] else r.uniform(0.0, 0.8)
    r = part("heave, pitch, roll")
    p["heave_lin"] *= r.uniform(0.6, 1.6)
    p["heave_quad"] *= r.uniform(0.7, 1.4)
    p["surface_damping"] = r.uniform(80.0, 160.0)
    for k in ("pitch_lin", "pitch_quad", "roll_lin", "roll_quad"):
        p[k] *= r.uniform(0.7, 1.4)
    for k in ("righting_pitch_nm", "righting_roll_nm"):
        p[k] *= r.uniform(0.7, 1.4)
    r = part("buoyancy")
    p["reserve_buoyancy_n"] = r.uniform(1.0, 2.0)
    p["top_above_com_m"] = r.uniform(0.21, 0.27)
    p["bottom_below_com_m"] = r.uniform(0.19, 0.25)
    p["waterplane_m2"] *= r.uniform(0.8, 1.2)
    p["cb_ahead_of_cg_m"] = r.uniform(-0.002, 0.002)
    p["cb_starboard_of_cg_m"] = r.uniform(-0.001, 0.001)
    p["thrust_line_above_com_m"] = r.uniform(0.01, 0.07)
    p["lever_horizontal_m"] *= r.uniform(0.93, 1.07)
    p["lever_vertical_m"] *= r.uniform(0.9, 1.1)
    r = part("sensor placement")
    sp["depth_port_body_m"] = [r.uniform(-0.60, -0.35), r.uniform(-0.05, 0.05), r.uniform(0.05, 0.20)]
    sp["accel_body_m"] = [r.uniform(0.0, 0.2), sp["accel_body_m"][1], sp["accel_body_m"][2]]
    sp["camera_marker_body_m"] = [r.uniform(-0.05, 0.15), r.uniform(-0.04, 0.04)]

    def sign(v):
        return "off" if v == 0.0 else ("positive" if v > 0.0 else "negative")

    b = p["mass_kg"] * POOL["g"] + p["reserve_buoyancy_n"]
    kinds = {
        "structure_seed": n,
        "surge_drag_law": "+".join(law),
        "top_speed_design_mps": top_mps,
        "surge_drag_grows_with_sway": p["surge_per_sway"] > 0.0,
        "sway_drag_cubic": p["sway_cubic"] > 0.0,
        "yaw_damping_cubic": p["yaw_cubic"] > 0.0,
        "munk_moment": p["munk_factor"] > 0.0,
        "sway_yaw_cross_damping": {"y_r": sign(p["y_r"]), "n_v": sign(p["n_v"])},
        "saturating_thrusters": [m["saturation"] < 1.0 for m in p["thruster_maps"]],
        "trim_deg": {  # where the righting moment balances the buoyancy's moment
            "pitch": math.degrees(math.atan(b * p["cb_ahead_of_cg_m"] / p["righting_pitch_nm"])),
            "roll": math.degrees(math.atan(-b * p["cb_starboard_of_cg_m"] / p["righting_roll_nm"]))},
        "float_depth_m": float_depth_m(p),
    }
    return p, sp, kinds


def draw_start_offset(r, float_shift_m=0.0):
    """(north m, east m, down m, heading deg) from stream `r`: the true start minus the stated
    one. The stated depth is the nominal float depth; the true one is the vehicle's own float
    depth (`float_shift_m` below the nominal one) plus U(-0.03, 0.26) m: released under water
    or bobbing, never dropped in from the air (the waterplane model would plunge it deep).
    Within START_OFFSET_LIMITS while |float_shift_m| <= 0.04."""
    horizontal, _, heading = START_OFFSET_LIMITS
    a, d = r.uniform(0.0, 2.0 * math.pi), horizontal * math.sqrt(r.random())
    return [d * math.cos(a), d * math.sin(a), float_shift_m + r.uniform(-0.03, 0.26),
            r.uniform(-heading, heading)]


def wrap180(a):
    return (a + 180.0) % 360.0 - 180.0


def stream(seed, name):
    """An independent random stream per noise source (str seeding is stable across runs)."""
    return random.Random(f"{seed}/{name}")


class OU:
    """Ornstein-Uhlenbeck process with exact discretisation; unit std unless scaled."""

    def __init__(self, rng, tau_s, dt_s, std=1.0):
        self.rng, self.x = rng, rng.gauss(0.0, std)
        self.a = math.exp(-dt_s / tau_s)
        self.b = std * math.sqrt(1.0 - self.a * self.a)

    def next(self):
        self.x = self.a * self.x + self.b * self.rng.gauss(0.0, 1.0)
        return self.x


# ---------------------------------------------------------------------------------------------
# The vehicle
# ---------------------------------------------------------------------------------------------
class Vehicle:
    def __init__(self, p, seed, x, y, heading_deg, z, current_ne):
        self.p = p
        self.x, self.y, self.psi, self.z = x, y, math.radians(heading_deg), z
        self.u = self.v = self.r = self.w = 0.0
        self.phi = self.theta = self.p_rate = self.q = 0.0
        self.du = self.dv = self.dw = self.dr = 0.0
        self.n = [0.0] * 4
        self.cmd = [0.0] * 4
        self.current = current_ne
        self.fluct = [OU(stream(seed, f"rpm{i}"), p["rpm_fluctuation_tau_s"], 0.05) for i in range(4)]
        self.fl = [0.0] * 4
        self.dist = [OU(stream(seed, f"dist{i}"), p["dist_tau_s"], 0.05) for i in range(4)]
        self.ds = [0.0] * 4
        self.contacts = 0
        self.in_contact = False
        self.walls = True
        self.maps = thruster_maps(p)
        self.up = [1.0 - math.exp(-DT_S / m["tau_spin_up_s"]) for m in self.maps]
        self.down = [1.0 - math.exp(-DT_S / m["tau_spin_down_s"]) for m in self.maps]
        self.n_ss = [0.0] * 4
        # terms only a drawn structure has (absent: the nominal equations, bit for bit)
        self.surge_per_sway = p.get("surge_per_sway", 0.0)
        self.sway_cubic = p.get("sway_cubic", 0.0)
        self.yaw_cubic = p.get("yaw_cubic", 0.0)
        self.munk = p.get("munk_factor", 1.0)
        b = p.get("mass_kg", 0.0) * POOL["g"] + p["reserve_buoyancy_n"]  # buoyancy submerged
        self.trim_pitch_nm = b * p.get("cb_ahead_of_cg_m", 0.0)
        self.trim_roll_nm = -b * p.get("cb_starboard_of_cg_m", 0.0)

    def command(self, percent):
        """MOTORDrive percent -> steady rpm fraction (deadband, saturation, motor curve)."""
        self.cmd = list(percent)
        for i, c in enumerate(percent):
            m = self.maps[i]
            f = abs(c) / 100.0
            if f <= m["deadband"]:
                self.n_ss[i] = 0.0
            else:
                x = min(1.0, (f - m["deadband"]) / (m["saturation"] - m["deadband"]))
                e = x ** (m["exponent_forward"] if c > 0 else m["exponent_reverse"])
                self.n_ss[i] = e if c > 0 else -e

    def slow_noise(self):
        """Called every 50 ms: advance the coloured noises (held between calls)."""
        self.fl = [o.next() for o in self.fluct]
        self.ds = [o.next() for o in self.dist]

    def thrusts(self):
        p, out = self.p, []
        for i in range(4):
            n = self.n[i] * (1.0 + p["rpm_fluctuation_rel"] * self.fl[i] * abs(self.n[i]))
            k = p["thrust_fwd_n"] * p["gains"][i] * (1.0 if n >= 0.0 else p["reverse_ratio"])
            out.append(k * n * abs(n))
        return out

    def step(self):
        p, dt = self.p, DT_S
        for i in range(4):
            a = self.up[i] if abs(self.n_ss[i]) > abs(self.n[i]) else self.down[i]
            self.n[i] += (self.n_ss[i] - self.n[i]) * a
        tp, ts, tb, tst = self.thrusts()
        c, s = math.cos(self.psi), math.sin(self.psi)
        uc = self.current[0] * c + self.current[1] * s
        vc = -self.current[0] * s + self.current[1] * c
        ur, vr, r = self.u - uc, self.v - vc, self.r
        m11, m22, m66 = p["m_surge_kg"], p["m_sway_kg"], p["i_yaw_kgm2"]
        fx = (tp + ts + m22 * vr * r
              - (p["surge_lin"] * ur + p["surge_quad"] * ur * abs(ur) + p["surge_cubic"] * ur ** 3)
              + p["dist_surge_n"] * self.ds[0])
        sway_drag = p["sway_lin"] * vr + p["sway_quad"] * vr * abs(vr)
        if self.surge_per_sway:  # surge resistance that grows with the sway speed
            fx -= self.surge_per_sway * ur * abs(vr)
        if self.sway_cubic:
            sway_drag += self.sway_cubic * vr ** 3
        fy = -m11 * ur * r - sway_drag - p["y_r"] * r + p["dist_sway_n"] * self.ds[1]
        nz = (p["lever_horizontal_m"] * (tp - ts) - self.munk * (m22 - m11) * ur * vr
              - ((p["yaw_lin"] + p["yaw_lin_per_speed"] * abs(ur)) * r + p["yaw_quad"] * r * abs(r))
              - (p["n_v"] + p["n_v_per_speed"] * ur) * vr
              + p["dist_yaw_nm"] * self.ds[2])
        if self.yaw_cubic:
            nz -= self.yaw_cubic * r ** 3
        # walls: only near them
        if self.walls and (self.x < 0.8 or self.y < 0.8 or self.x > POOL["length_m"] - 0.8
                or self.y > POOL["width_m"] - 0.8):
            cfx, cfy, cnz = self.wall_forces(c, s)
            fx, fy, nz = fx + cfx, fy + cfy, nz + cnz
        elif self.in_contact:
            self.in_contact = False
        # heave, pitch, roll
        emerge = p["top_above_com_m"] - self.z
        fz = tb + tst - p["reserve_buoyancy_n"] - p["heave_lin"] * self.w - p["heave_quad"] * self.w * abs(self.w)
        if emerge > 0.0:
            fz += POOL["rho"] * POOL["g"] * p["waterplane_m2"] * min(emerge, 0.46)
            fz -= p["surface_damping"] * self.w
        floor = self.z + p["bottom_below_com_m"] - POOL["depth_m"]
        if floor > 0.0:
            fz -= p["wall_stiffness_npm"] * floor + p["wall_damping_nspm"] * self.w
        fz += p["dist_heave_n"] * self.ds[3]
        my = (p["lever_vertical_m"] * (tst - tb) - p["thrust_line_above_com_m"] * (tp + ts)
              - p["righting_pitch_nm"] * math.sin(self.theta)
              - p["pitch_lin"] * self.q - p["pitch_quad"] * self.q * abs(self.q))
        mx = (0.06 * sway_drag - p["righting_roll_nm"] * math.sin(self.phi)
              - p["roll_lin"] * self.p_rate - p["roll_quad"] * self.p_rate * abs(self.p_rate))
        if self.trim_pitch_nm or self.trim_roll_nm:  # centre of buoyancy off the CG's vertical
            my += self.trim_pitch_nm * math.cos(self.theta)
            mx += self.trim_roll_nm * math.cos(self.phi)
        # semi-implicit Euler: velocities first, positions with the new velocities. The forces
        # above act on the water-relative velocity; u and v are over the ground, so they also
        # carry the steady current's turn in the body frame (d(uc)/dt = r vc, d(vc)/dt = -r uc):
        # a hull that moves with the water keeps moving with it however it turns.
        self.du, self.dv, self.dr = fx / m11 + r * vc, fy / m22 - r * uc, nz / m66
        self.dw = fz / p["m_heave_kg"]
        self.u += dt * self.du
        self.v += dt * self.dv
        self.r += dt * self.dr
        self.w += dt * self.dw
        self.q += dt * my / p["i_pitch_kgm2"]
        self.p_rate += dt * mx / p["i_roll_kgm2"]
        self.x += dt * (self.u * c - self.v * s)
        self.y += dt * (self.u * s + self.v * c)
        self.psi += dt * self.r
        self.z += dt * self.w
        self.theta += dt * self.q
        self.phi += dt * self.p_rate

    def wall_forces(self, c, s):
        p = self.p
        fxw = fyw = nz = 0.0
        touching = False
        for bx in (0.67, -0.67):
            for by in (0.32, -0.32):
                px = self.x + bx * c - by * s
                py = self.y + bx * s + by * c
                vx = self.u * c - self.v * s - self.r * (bx * s + by * c)
                vy = self.u * s + self.v * c + self.r * (bx * c - by * s)
                fx_c = fy_c = 0.0
                if px < 0.0:
                    fx_c = max(0.0, -p["wall_stiffness_npm"] * px - p["wall_damping_nspm"] * vx)
                elif px > POOL["length_m"]:
                    fx_c = min(0.0, -p["wall_stiffness_npm"] * (px - POOL["length_m"]) - p["wall_damping_nspm"] * vx)
                if py < 0.0:
                    fy_c = max(0.0, -p["wall_stiffness_npm"] * py - p["wall_damping_nspm"] * vy)
                elif py > POOL["width_m"]:
                    fy_c = min(0.0, -p["wall_stiffness_npm"] * (py - POOL["width_m"]) - p["wall_damping_nspm"] * vy)
                if fx_c or fy_c:
                    touching = True
                    fbx = fx_c * c + fy_c * s
                    fby = -fx_c * s + fy_c * c
                    fxw += fbx
                    fyw += fby
                    nz += bx * fby - by * fbx
        if touching and not self.in_contact:
            self.contacts += 1
        self.in_contact = touching
        return fxw, fyw, nz

    def specific_force(self, at):
        """Body-frame specific force (m/s^2) at body point `at`: kinematic acceleration minus
        gravity; at rest and level (0, 0, -g)."""
        g, bx = POOL["g"], at[0]
        fx = self.du - self.v * self.r - self.r * self.r * bx + g * math.sin(self.theta)
        fy = self.dv + self.u * self.r + self.dr * bx - g * math.sin(self.phi) * math.cos(self.theta)
        fz = self.dw - g * math.cos(self.phi) * math.cos(self.theta)
        return fx, fy, fz


# ---------------------------------------------------------------------------------------------
# Sensors (each with its own random stream)
# ---------------------------------------------------------------------------------------------
class Sensors:
    def __init__(self, sp, seed, eff):
        self.sp, self.eff = sp, eff
        self.lsb_v = sp["adc_ref_v"] / sp["adc_codes"]
        self.rng_adc = stream(seed, "adc")
        self.rng_depth = stream(seed, "depth")
        self.rng_accel = stream(seed, "accel")
        self.rng_compass = stream(seed, "compass")
        self.rng_camera = stream(seed, "camera")
        self.rng_sonar = stream(seed, "sonar")
        self.depth_v = None  # low-passed sensor voltage
        # paddle wheel
        self.wheel_mps = 0.0
        self.wheel_phase = stream(seed, "paddle").random()
        self.pulse_high = False
        self.pulses = 0
        self.paddle_value = None
        # compass pipeline: (ready tick, integer heading)
        self.compass_mx = 0.0
        self.compass_queue = []
        self.compass_latest = None
        self.compass_seq = 0
        inc, dec = math.radians(sp["inclination_deg"]), math.radians(sp["declination_deg"])
        h = sp["field_ut"] * math.cos(inc)
        self.earth = (h * math.cos(dec), h * math.sin(dec), sp["field_ut"] * math.sin(inc))
        hi = sp["residual_hard_iron_ut"]
        self.hard = [hi[0] + eff.hard_iron[0], hi[1] + eff.hard_iron[1]]
        self.sonar_queue = []  # (ready tick, transducer index, range)

    def adc_code(self, volts):
        v = volts + self.rng_adc.gauss(0.0, self.sp["adc_board_noise_v"])
        return min(self.sp["adc_codes"] - 1, max(0, int(math.floor(v / self.lsb_v))))

    # depth -------------------------------------------------------------------------------
    def depth_port_m(self, veh):
        bx, by, bz = self.sp["depth_port_body_m"]
        d = veh.z - bx * math.sin(veh.theta) + bz * math.cos(veh.theta) * math.cos(veh.phi)
        if by:
            d += by * math.cos(veh.theta) * math.sin(veh.phi)
        return d

    def depth_track(self, veh):
        """Every physics step: the sensor's front end (gauge pressure, amplifier, RC filter)."""
        sp, e = self.sp, self.eff
        d = max(0.0, self.depth_port_m(veh))
        v = (d * sp["depth_gain_v_per_m"] * (1.0 + e.depth_gain)
             + sp["depth_offset_v"] + e.depth_offset_m * sp["depth_gain_v_per_m"])
        if self.depth_v is None:
            self.depth_v = v
        self.depth_v += (v - self.depth_v) * (DT_S / (sp["depth_tau_s"] + DT_S))

    def read_depth(self, veh):
        sp = self.sp
        duty = abs(veh.cmd[3]) / 100.0
        emi = (sp["depth_emi_v_full_duty"] + self.eff.depth_emi_v) * duty
        v = self.depth_v + self.rng_depth.gauss(0.0, math.hypot(sp["depth_noise_v"], emi))
        return self.adc_code(v)

    # accelerometer -----------------------------------------------------------------------
    def read_accel(self, veh):
        sp = self.sp
        fx, fy, fz = veh.specific_force(sp["accel_body_m"])
        ay, az = (math.radians(a) for a in sp["accel_misalign_deg"])
        fx, fy = fx * math.cos(az) + fy * math.sin(az), -fx * math.sin(az) + fy * math.cos(az)
        fx, fz = fx * math.cos(ay) - fz * math.sin(ay), fx * math.sin(ay) + fz * math.cos(ay)
        vib = sp["accel_vibration_g"] * max(abs(n) for n in veh.n)
        codes = []
        for k, f in enumerate((fx, fy, fz)):
            g = f / 9.80665 + self.rng_accel.gauss(0.0, vib)
            v = (sp["accel_zero_g_v"][k] + self.eff.accel_offset_v[k] + sp["accel_v_per_g"][k] * g
                 + self.rng_accel.gauss(0.0, sp["accel_noise_v"]))
            codes.append(self.adc_code(min(2.85, max(0.45, v))))
        return codes

    # paddle wheel ------------------------------------------------------------------------
    def paddle_step(self, veh):
        """Every physics step: the wheel's own inertia, stall and slip."""
        sp = self.sp
        c, s = math.cos(veh.psi), math.sin(veh.psi)
        ur = veh.u - (veh.current[0] * c + veh.current[1] * s)
        a = abs(ur)
        target = 0.0 if a < sp["paddle_stall_mps"] else sp["paddle_slip"] * (a - sp["paddle_stall_mps"])
        self.wheel_mps += (target - self.wheel_mps) * (DT_S / sp["paddle_tau_s"])
        self.wheel_phase += self.wheel_mps * sp["paddle_pulses_per_m"] * DT_S

    def paddle_poll(self):
        """The firmware's 10 ms poll: a rising edge of the pulse line is one half turn."""
        high = (self.wheel_phase % 1.0) < 0.5
        if high and not self.pulse_high:
            self.pulses += 1
        self.pulse_high = high

    def paddle_window_end(self):
        sp = self.sp
        self.paddle_value = (self.pulses * sp["firmware_m_per_pulse"] / sp["window_s"]
                             * (1.0 + self.eff.velocity_scale))
        self.pulses = 0

    # compass ------------------------------------------------------------------------------
    def body_field(self, veh):
        e = self.earth
        cp, sp_ = math.cos(veh.psi), math.sin(veh.psi)
        ct, st = math.cos(veh.theta), math.sin(veh.theta)
        cf, sf = math.cos(veh.phi), math.sin(veh.phi)
        # world -> body: yaw, then pitch, then roll
        x1 = cp * e[0] + sp_ * e[1]
        y1 = -sp_ * e[0] + cp * e[1]
        z1 = e[2]
        x2 = ct * x1 - st * z1
        z2 = st * x1 + ct * z1
        y3 = cf * y1 + sf * z2
        return x2, y3

    def compass_sample_x(self, veh):
        self.compass_mx = self.body_field(veh)[0]

    def compass_sample_y(self, veh, tick):
        sp = self.sp
        _, by = self.body_field(veh)
        bx = self.compass_mx
        si = sp["soft_iron"]
        mx = si[0][0] * bx + si[0][1] * by + self.hard[0] + self.rng_compass.gauss(0.0, sp["compass_noise_ut"])
        my = si[1][0] * bx + si[1][1] * by + self.hard[1] + self.rng_compass.gauss(0.0, sp["compass_noise_ut"])
        heading = math.degrees(math.atan2(-my, mx)) + self.eff.compass_offset_deg
        value = int(math.floor(heading % 360.0 + 0.5)) % 360
        ready = tick + round((sp["compass_ready_s"] - sp["compass_xy_gap_s"] + self.eff.compass_latency_s) * TICKS_PER_S)
        self.compass_queue.append((ready, value))

    def compass_deliver(self, tick):
        while self.compass_queue and self.compass_queue[0][0] <= tick:
            self.compass_latest = self.compass_queue.pop(0)[1]
            self.compass_seq += 1

    # camera -------------------------------------------------------------------------------
    def camera_frame(self, veh):
        sp = self.sp
        if self.rng_camera.random() < sp["camera_dropout"]:
            return None
        mx, my = sp["camera_marker_body_m"]
        c, s = math.cos(veh.psi), math.sin(veh.psi)
        x = veh.x + mx * c - my * s + self.rng_camera.gauss(0.0, sp["camera_std_m"])
        y = veh.y + mx * s + my * c + self.rng_camera.gauss(0.0, sp["camera_std_m"])
        return round(x, 3), round(y, 3)  # the tracker reports millimetres

    # sonar --------------------------------------------------------------------------------
    def sonar_ping(self, veh, k, tick):
        """Transducer k pings; a valid echo becomes a reading after the multiplexer latency."""
        sp = self.sp
        _, bx, by, az = sp["sonar_mount"][k]
        c, s = math.cos(veh.psi), math.sin(veh.psi)
        tx = veh.x + bx * c - by * s
        ty = veh.y + bx * s + by * c
        beam = math.degrees(veh.psi) + az
        best = None
        # each wall: (outward normal bearing deg, perpendicular distance from the transducer)
        for normal, dist in ((0.0, POOL["length_m"] - tx), (180.0, tx),
                             (90.0, POOL["width_m"] - ty), (270.0, ty)):
            if dist <= 0.0:
                continue
            beta = abs(wrap180(beam - normal))
            if beta > sp["sonar_max_incidence_deg"]:
                continue
            edge = max(0.0, beta - sp["sonar_half_beam_deg"])
            rng = dist / math.cos(math.radians(edge))
            if best is None or rng < best[0]:
                best = (rng, beta)
        if best is None:
            return
        rng, beta = best
        if rng < sp["sonar_min_range_m"]:
            return
        speed = math.hypot(veh.u, veh.v)
        p_det = (0.99 / (1.0 + math.exp((rng - sp["sonar_range_half_m"]) / sp["sonar_range_width_m"]))
                 * math.exp(-0.5 * (beta / sp["sonar_incidence_sigma_deg"]) ** 2)
                 / (1.0 + (speed / sp["sonar_speed_half_mps"]) ** 2))
        if self.rng_sonar.random() >= p_det:
            return
        meas = rng + self.rng_sonar.gauss(0.0, sp["sonar_noise_m"])
        meas = round(meas / sp["sonar_resolution_m"]) * sp["sonar_resolution_m"]
        ready = tick + round(sp["sonar_latency_s"] * TICKS_PER_S)
        self.sonar_queue.append((ready, k, round(meas, 1)))


# ---------------------------------------------------------------------------------------------
# Hidden effects
# ---------------------------------------------------------------------------------------------
class Effects:
    """The hidden effects of a run: one (`name`, `size`), or several (`parts`, a list of
    (name, size); then `name` is their names joined by "+" and `size` the list of sizes)."""

    def __init__(self, name, size, parts=None):
        self.name, self.size = name, size
        self.parts = [(name, size)] if parts is None else list(parts)
        self.current = [0.0, 0.0]
        self.hard_iron = [0.0, 0.0]
        self.compass_latency_s = 0.0
        self.compass_offset_deg = 0.0
        self.depth_emi_v = 0.0
        self.depth_offset_m = 0.0
        self.depth_gain = 0.0
        self.accel_offset_v = [0.0, 0.0, 0.0]
        self.velocity_scale = 0.0
        for n, s in self.parts:
            self.apply_sensor_effect(n, s)

    @classmethod
    def several(cls, parts):
        """Several effects at once; a single part gives the same object as `Effects(name, size)`."""
        if len(parts) == 1:
            return cls(*parts[0])
        return cls("+".join(n for n, _ in parts), [s for _, s in parts], parts)

    def apply_sensor_effect(self, name, size):
        if name == "water_current":
            self.current = list(size)
        elif name == "compass_hard_iron":
            self.hard_iron = list(size)
        elif name == "compass_latency":
            self.compass_latency_s = size
        elif name == "compass_offset":
            self.compass_offset_deg = size
        elif name == "depth_emi":
            self.depth_emi_v = size
        elif name == "depth_offset":
            self.depth_offset_m = size
        elif name == "depth_gain":
            self.depth_gain = size
        elif name == "accel_offset":
            self.accel_offset_v = list(size)
        elif name == "velocity_sensor_scale":
            self.velocity_scale = size

    def vehicle_params(self, base):
        """`base` (NOMINAL or a drawn structure) with the hidden vehicle effects applied."""
        p = json.loads(json.dumps(base))
        for n, s in self.parts:
            if n == "thruster_imbalance":
                p["gains"][0] *= 1.0 + s / 2.0
                p["gains"][1] *= 1.0 - s / 2.0
            elif n == "thrust_gain":
                p["thrust_fwd_n"] *= 1.0 + s
            elif n == "thruster_lag":
                if "thruster_maps" in p:
                    for m in p["thruster_maps"]:
                        m["tau_spin_up_s"] += s
                        m["tau_spin_down_s"] += s
                else:
                    p["tau_spin_up_s"] += s
                    p["tau_spin_down_s"] += s
            elif n == "drag":
                for k in ("surge_lin", "surge_quad", "surge_cubic", "sway_lin", "sway_quad",
                          "surge_per_sway", "sway_cubic"):
                    if k in p:
                        p[k] *= s
            elif n == "yaw_damping":
                for k in ("yaw_lin", "yaw_quad", "yaw_cubic"):
                    if k in p:
                        p[k] *= s
            elif n == "sway_yaw_coupling":
                p["n_v"] += s
        return p


def thruster_maps(p):
    """Per-thruster command -> rpm maps: a drawn structure's own, or the nominal one four times."""
    if "thruster_maps" in p:
        return p["thruster_maps"]
    return [{"deadband": p["deadband"], "saturation": 1.0, "exponent_forward": p["rpm_exponent"],
             "exponent_reverse": p["rpm_exponent"], "tau_spin_up_s": p["tau_spin_up_s"],
             "tau_spin_down_s": p["tau_spin_down_s"]} for _ in range(4)]


def float_depth_m(p):
    """Depth of the centre of mass when the vehicle floats at rest, motors off: the top of the
    hull emerges until the lost displacement equals the reserve buoyancy."""
    return p["top_above_com_m"] - p["reserve_buoyancy_n"] / (POOL["rho"] * POOL["g"] * p["waterplane_m2"])


# ---------------------------------------------------------------------------------------------
# The EyeBot: what a program can read and command, and the log it keeps
# ---------------------------------------------------------------------------------------------
class EyeBot:
    def __init__(self, veh, sen, camera):
        self.veh, self.sen = veh, sen
        self.t = 0.0
        self.tick = 0
        self.duration_s = 0.0
        self.cmd = [0, 0, 0, 0]
        self.commands = []  # (t, [4])
        self.rows = {}  # tick -> {column: text}
        self.camera = camera
        self.compass_seen = 0
        self.paddle_new = None
        self.sonar_new = {}
        self.depth_code = None

    def log(self, tick, col, text):
        self.rows.setdefault(tick, {})[col] = text

    # RoBIOS-like calls used by the programs
    def motor_drive(self, port, starboard, bow, stern):
        new = [max(-100, min(100, int(round(v)))) for v in (port, starboard, bow, stern)]
        if new != self.cmd or not self.commands:
            self.cmd = new
            self.commands.append((self.tick, list(new)))
            self.veh.command(new)

    def compass_get(self):
        """(new reading since the last call?, latest heading 0..359 or None)."""
        new = self.sen.compass_seq != self.compass_seen
        self.compass_seen = self.sen.compass_seq
        if new:
            self.log(self.tick, "compass_deg", str(self.sen.compass_latest))
        return new, self.sen.compass_latest

    def depth_adc(self):
        self.depth_code = self.sen.read_depth(self.veh)
        return self.depth_code

    def depth_m(self, code):
        """The student's conversion: 5 V over 1024 codes, 1 V per metre, no offset."""
        return code * 5.0 / 1024.0

    def paddle(self):
        v, self.paddle_new = self.paddle_new, None
        return v

    def sonar(self, k):
        return self.sonar_new.pop(k, None)


# ---------------------------------------------------------------------------------------------
# Control programs (each `step` runs once per control period on measured sensors only)
# ---------------------------------------------------------------------------------------------
class Heading:
    """PD on the compass, derivative from successive readings, as a student would write."""

    def __init__(self, kp=1.6, kd=2.5, limit=60.0):
        self.kp, self.kd, self.limit = kp, kd, limit
        self.rate = 0.0
        self.heading = None
        self.new = False
        self.tick = None

    def update(self, eb):
        """Reads the compass once per control period (later calls in the period reuse it)."""
        if self.tick == eb.tick:
            return self.heading
        self.tick = eb.tick
        self.new, h = eb.compass_get()
        if self.new and h is not None:
            if self.heading is not None:
                self.rate = 0.6 * self.rate + 0.4 * wrap180(h - self.heading) / 0.4
            self.heading = h
        return self.heading

    def output(self, desired):
        if self.heading is None:
            return 0.0
        e = wrap180(desired - self.heading)
        d = self.kp * e - self.kd * self.rate
        return max(-self.limit, min(self.limit, d))


class TurnCounter:
    """Accumulates the heading change between compass readings (turns counted on the compass)."""

    def __init__(self):
        self.turned, self.last = 0.0, None

    def feed(self, hc):
        if hc.new and hc.heading is not None:
            if self.last is not None:
                self.turned += wrap180(hc.heading - self.last)
            self.last = hc.heading


class Depth:
    """PID on the depth ADC with a feed-forward for the reserve buoyancy."""

    def __init__(self, period_s, ff=62.0, kp=200.0, ki=15.0, kd=400.0):
        self.dt, self.ff, self.kp, self.ki, self.kd = period_s, ff, kp, ki, kd
        self.i = 0.0
        self.filt = None
        self.prev = None
        self.rate = 0.0

    def output(self, eb, target_m):
        d = eb.depth_m(eb.depth_adc())
        self.filt = d if self.filt is None else self.filt + 0.3 * (d - self.filt)
        if self.prev is not None:
            self.rate = 0.85 * self.rate + 0.15 * (self.filt - self.prev) / self.dt
        self.prev = self.filt
        e = target_m - self.filt
        if abs(e) < 0.15:  # integrate only near the target (the student's anti-windup)
            self.i = max(-1.5, min(1.5, self.i + e * self.dt))
        out = self.ff + self.kp * e + self.ki * self.i - self.kd * self.rate
        return max(-100.0, min(100.0, out))


class Program:
    """An EyeBot program: it learns its start heading from the first compass reading (motors
    off until then), then `step` runs once per control period."""
    period_s = 0.05

    def __init__(self, rng):
        self.rng = rng
        self.h0 = None
        self.hc = Heading()

    def run(self, eb, t):
        if self.h0 is None:
            h = self.hc.update(eb)
            if h is None:
                eb.motor_drive(0, 0, 0, 0)
                return
            self.h0 = float(h)
            self.begin()
        self.step(eb, t)

    def begin(self):
        """Called once the start heading is known."""

    def floating(self, eb, t):
        """Motors off at the surface before the dive and after the run, the depth channel's
        only absolute reference; True while floating."""
        if t < FLOAT_START_S or t >= eb.duration_s - FLOAT_END_S:
            eb.depth_adc()
            self.t0 = t
            self.note_target(t, 0.0)
            eb.motor_drive(0, 0, 0, 0)
            return True
        return False

    def note_target(self, t, target):
        """Keeps (start, end, depth target) stretches for the summary."""
        if not hasattr(self, "log"):
            self.log = []
        if not self.log or self.log[-1][2] != target:
            if self.log:
                self.log[-1] = (self.log[-1][0], t, self.log[-1][2])
            self.log.append((t, None, target))


class HeadingHold(Program):
    """Out-and-back legs: turn on the spot to the new heading (compass), then drive a timed leg
    holding it; the heading steps between pairs of legs are 45-120 deg, speeds 40-100 %."""

    def __init__(self, rng):
        super().__init__(rng)
        self.k = 0
        self.state, self.t0, self.t_ok = "leg", 0.0, None

    def begin(self):
        rng, h0 = self.rng, self.h0
        bases = [50, 80, 65, 100, 40, 90]
        self.legs = []
        ang = 0.0
        for k in range(40):
            b = bases[k % len(bases)]
            leg = (6.0 if b >= 80 else 9.0) + 3.0 * rng.random()
            # the pool is half as wide as it is long: shorter legs across it
            leg *= 0.45 + 0.55 * abs(math.cos(math.radians(h0 + ang)))
            self.legs.append((ang, b, leg))
            self.legs.append((ang + 180.0, b, leg))
            ang += rng.choice([45.0, 60.0, 90.0, -60.0, 120.0])

    def step(self, eb, t):
        self.hc.update(eb)
        ang, base, dur = self.legs[self.k]
        want = (self.h0 + ang) % 360.0
        if self.state == "turn":
            err = abs(wrap180(want - self.hc.heading)) if self.hc.heading is not None else 0.0
            self.t_ok = (self.t_ok or t) if err < 8.0 else None
            if (self.t_ok is not None and t - self.t_ok >= 1.0) or t - self.t0 > 45.0:
                self.state, self.t0 = "leg", t
            self.hc.limit = 80.0
            d = self.hc.output(want)
            eb.motor_drive(d, -d, 0, 0)
            return
        self.hc.limit = 40.0
        d = self.hc.output(want)
        eb.motor_drive(base + d, base - d, 0, 0)
        if t - self.t0 >= dur:
            self.k, self.state, self.t0, self.t_ok = self.k + 1, "turn", t, None


class Spins(Program):
    def __init__(self, rng):
        super().__init__(rng)
        self.plan = []
        for power, sign in ((100, 1), (100, -1), (60, 1), (60, -1), (100, -1), (80, 1)):
            self.plan.append(("turn", power, sign, 2 if power == 100 else 1))
            self.plan.append(("rest", 0, 0, 8.0 + 4.0 * rng.random()))
        self.k = 0
        self.count = TurnCounter()
        self.t0 = 0.0

    def step(self, eb, t):
        self.hc.update(eb)
        kind, power, sign, amount = self.plan[self.k % len(self.plan)]
        if kind == "turn":
            self.count.feed(self.hc)
            if abs(self.count.turned) >= 360.0 * amount - 5.0:
                self.k, self.count, self.t0 = self.k + 1, TurnCounter(), t
                eb.motor_drive(0, 0, 0, 0)
                return
            eb.motor_drive(sign * power, -sign * power, 0, 0)
        else:
            eb.motor_drive(0, 0, 0, 0)
            if t - self.t0 >= amount:
                self.k, self.count = self.k + 1, TurnCounter()


class DepthHold(Program):
    def __init__(self, rng):
        super().__init__(rng)
        self.dc = Depth(self.period_s)
        self.targets = []
        for _ in range(30):
            self.targets.append((20.0 + 10.0 * rng.random(), rng.choice([0.6, 0.9, 1.2, 1.5, 0.8, 1.1])))
        self.k, self.t0 = 0, 0.0

    def step(self, eb, t):
        self.hc.update(eb)
        if self.floating(eb, t):
            return
        if t - self.t0 >= self.targets[self.k][0]:
            self.k, self.t0 = self.k + 1, t
        self.note_target(t, self.targets[self.k][1])
        v = self.dc.output(eb, self.targets[self.k][1])
        d = self.hc.output(self.h0)
        eb.motor_drive(d, -d, v, v)


class Square(Program):
    def __init__(self, rng, leg_s=10.0, base=70.0, dive_m=None):
        super().__init__(rng)
        self.leg_s, self.base = leg_s, base
        self.dc = Depth(self.period_s) if dive_m else None
        self.dive_m = dive_m
        self.side = 0
        self.direction = 1
        self.state, self.t0 = "leg", 0.0
        self.want = None

    def begin(self):
        self.want = self.h0

    def step(self, eb, t):
        self.hc.update(eb)
        v = self.dc.output(eb, self.dive_m) if self.dc else 0.0
        if self.state == "leg":
            d = self.hc.output(self.want)
            eb.motor_drive(self.base + d, self.base - d, v, v)
            if t - self.t0 >= self.leg_s:
                self.side += 1
                if self.side % 8 == 0:
                    self.direction = -self.direction
                self.want = (self.want + 90.0 * self.direction) % 360.0
                self.state, self.t0 = "turn", t
        elif self.state == "turn":
            h = self.hc.heading
            err = wrap180(self.want - h) if h is not None else 0.0
            if abs(err) < 8.0:
                self.state, self.t0 = "settle", t
            p = 60.0 if err > 0 else -60.0
            eb.motor_drive(p, -p, v, v)
        else:
            d = self.hc.output(self.want)
            eb.motor_drive(d, -d, v, v)
            if t - self.t0 >= 3.0:
                self.state, self.t0 = "leg", t


class WallRun(Program):
    """Wall on port held at 1.0 m on sonar 1 (port-fore, 15 deg ahead of the beam); a wall ahead
    on sonar 3 (bow-port) closer than 3.5 m starts a 90 deg right turn by compass. The heading
    correction is kept inside what the transducer still hears (turning away by more than
    ~5 deg loses the echo); without a side echo for 3 s the program steers along the wall."""
    select = (0, 2)  # controller 0 -> port-fore, controller 1 -> bow-port

    def __init__(self, rng):
        super().__init__(rng)
        self.turning = False
        self.base = 55.0
        self.corners = 0
        self.t_side = 0.0

    def begin(self):  # the student put Mako along the wall: the first reading is its heading
        self.wall = self.want = self.h0

    def step(self, eb, t):
        self.hc.update(eb)
        side, ahead = eb.sonar(0), eb.sonar(2)
        if not self.turning:
            if side is not None:
                corr = max(-20.0, min(6.0, -30.0 * (side - 1.0)))
                self.want = (self.wall + corr) % 360.0
                self.t_side = t
            elif t - self.t_side > 3.0:
                self.want = self.wall
            if ahead is not None and ahead < 3.5:
                self.wall = (self.wall + 90.0) % 360.0
                self.want = self.wall
                self.turning = True
                self.corners += 1
        h = self.hc.heading
        if self.turning:
            err = wrap180(self.want - h) if h is not None else 0.0
            if abs(err) < 10.0:
                self.turning = False
                self.t_side = t
            p = 60.0 if err > 0 else -60.0
            eb.motor_drive(p, -p, 0, 0)
            return
        d = self.hc.output(self.want)
        eb.motor_drive(self.base + d, self.base - d, 0, 0)


class Mixed(Program):
    """Dive to 1 m, out and back at depth, a spot turn each way, then squares at 0.7 m."""

    def __init__(self, rng):
        super().__init__(rng)
        self.dc = Depth(self.period_s)
        self.phase = 0
        self.t0 = 0.0
        self.square = Square(rng, leg_s=8.0, base=70.0, dive_m=0.7)
        self.square.hc = self.hc
        self.square.dc = self.dc
        self.count = TurnCounter()
        self.t_aligned = None

    def begin(self):
        self.square.h0 = self.h0
        self.square.begin()

    def step(self, eb, t):
        self.hc.update(eb)
        if self.floating(eb, t):
            return
        dt = t - self.t0
        self.note_target(t, 0.7 if self.phase >= 6 else 1.0)
        if self.phase >= 6:
            if self.phase == 6:  # the squares start now
                self.phase, self.square.t0 = 7, t
            self.square.step(eb, t)
            return
        v = self.dc.output(eb, 1.0)
        if self.phase == 0:  # dive, hold heading
            d = self.hc.output(self.h0)
            eb.motor_drive(d, -d, v, v)
            if dt > 20.0:
                self.phase, self.t0 = 1, t
        elif self.phase in (1, 2):  # out and back at depth, along the pool
            want = self.h0 + (0.0 if self.phase == 1 else 180.0)
            err = abs(wrap180(want - (self.hc.heading if self.hc.heading is not None else want)))
            b = 75.0 if err < 20.0 else 0.0
            if b and self.t_aligned is None:
                self.t_aligned = t
            d = self.hc.output(want)
            eb.motor_drive(b + d, b - d, v, v)
            if self.t_aligned is not None and t - self.t_aligned > 12.0:
                self.phase, self.t0, self.t_aligned = self.phase + 1, t, None
        elif self.phase in (3, 5):  # one spot turn each way, counted on the compass
            sign = 1 if self.phase == 3 else -1
            self.count.feed(self.hc)
            eb.motor_drive(sign * 100, -sign * 100, v, v)
            if abs(self.count.turned) >= 355.0:
                self.phase, self.t0, self.count = self.phase + 1, t, TurnCounter()
        else:  # settle between the spins
            d = self.hc.output(self.h0)
            eb.motor_drive(d, -d, v, v)
            if dt > 6.0:
                self.phase, self.t0 = self.phase + 1, t


FLOAT_START_S = 5.0  # s, depth programs float with the motors off before diving
FLOAT_END_S = 15.0  # s, and let the vehicle rise at the end


PROGRAM_CLASSES = {"heading_hold": HeadingHold, "spins": Spins, "depth_hold": DepthHold,
                   "square": Square, "wall_run": WallRun, "mixed": Mixed}


# ---------------------------------------------------------------------------------------------
# The run
# ---------------------------------------------------------------------------------------------
def start_pose(program, rng):
    if program == "wall_run":
        return 2.0 + 0.5 * rng.random(), 1.4 + 0.2 * rng.random(), 0.0 + rng.uniform(-3.0, 3.0)
    if program == "square":
        return 12.0 + 1.0 * rng.random(), 5.75 + 1.0 * rng.random(), rng.choice([0.0, 90.0, 180.0, 270.0]) + rng.uniform(-10, 10)
    if program == "mixed":  # its long legs run along the pool
        return 10.5 + 4.0 * rng.random(), 5.5 + 1.5 * rng.random(), rng.choice([0.0, 180.0]) + rng.uniform(-15, 15)
    return 10.5 + 4.0 * rng.random(), 5.5 + 1.5 * rng.random(), rng.uniform(0.0, 360.0)


def simulate(program, seed, duration_s, effect, camera=True, structure=None, offset=None):
    """One run. `structure` is (params, sensors) from `draw_structure` (None: NOMINAL and
    SENSORS); `offset` (north m, east m, down m, heading deg) moves the true start away from
    the stated one, the nominal vehicle floating at rest."""
    rng = stream(seed, "program")
    x0, y0, h0 = start_pose(program, rng)
    h0 %= 360.0
    base, sp = structure if structure is not None else (NOMINAL, SENSORS)
    p = effect.vehicle_params(base)
    z0 = float_depth_m(NOMINAL)
    true = (x0, y0, z0, h0)
    if offset is not None:
        true = (x0 + offset[0], y0 + offset[1], z0 + offset[2], (h0 + offset[3]) % 360.0)
    xt, yt, zt, ht = true
    veh = Vehicle(p, seed, xt, yt, ht, zt, effect.current)
    sen = Sensors(sp, seed, effect)
    eb = EyeBot(veh, sen, camera)
    eb.duration_s = duration_s
    prog = PROGRAM_CLASSES[program](stream(seed, "plan"))
    period = round(prog.period_s * TICKS_PER_S)
    compass_period = round(sp["compass_period_s"] * TICKS_PER_S)
    compass_phase = stream(seed, "compass-phase").randrange(compass_period)
    compass_gap = round(sp["compass_xy_gap_s"] * TICKS_PER_S)
    cam_period = round(sp["camera_period_s"] * TICKS_PER_S)
    cam_phase = stream(seed, "camera-phase").randrange(cam_period)
    sonar_period = round(sp["sonar_period_s"] * TICKS_PER_S)
    sonar_phase = [stream(seed, f"sonar-phase{c}").randrange(sonar_period) for c in (0, 1)]
    selected = getattr(prog, "select", None)
    poll = round(sp["poll_s"] * TICKS_PER_S)
    window = round(sp["window_s"] * TICKS_PER_S)
    n_ticks = round(duration_s * TICKS_PER_S)
    track = []  # (t, x, y, z, heading, u, v, r) every 0.1 s, for summaries
    depth_track = sen.depth_track
    paddle_step = sen.paddle_step
    vstep = veh.step
    for tick in range(n_ticks + 1):
        t = tick / TICKS_PER_S
        eb.tick, eb.t = tick, t
        depth_track(veh)
        paddle_step(veh)
        # sensor events at this tick
        if tick % poll == 0:
            sen.paddle_poll()
        if tick > 0 and tick % window == 0:
            sen.paddle_window_end()
            eb.paddle_new = sen.paddle_value
            eb.log(tick, "paddle_speed_mps", f"{sen.paddle_value:.4f}")
        k = (tick - compass_phase) % compass_period
        if k == 0:
            sen.compass_sample_x(veh)
        elif k == compass_gap:
            sen.compass_sample_y(veh, tick)
        sen.compass_deliver(tick)
        if camera and (tick - cam_phase) % cam_period == 0 and tick >= cam_phase:
            xy = sen.camera_frame(veh)
            if xy is not None:
                eb.log(tick, "x_m", f"{xy[0]:.3f}")
                eb.log(tick, "y_m", f"{xy[1]:.3f}")
        if selected is not None:
            for c in (0, 1):
                if tick >= sonar_phase[c] and (tick - sonar_phase[c]) % sonar_period == 0:
                    sen.sonar_ping(veh, selected[c], tick)
            while sen.sonar_queue and sen.sonar_queue[0][0] <= tick:
                _, kk, r = sen.sonar_queue.pop(0)
                eb.sonar_new[kk] = r
                eb.log(tick, f"sonar{kk + 1}_m", f"{r:.1f}")
        # the program
        if tick % period == 0 and tick < n_ticks:
            prog.run(eb, t)
            if tick % (2 * period) == 0:  # the logging task: depth and accelerometer at 10 Hz
                code = eb.depth_code if eb.depth_code is not None else eb.depth_adc()
                eb.depth_code = None
                eb.log(tick, "depth_adc", str(code))
                for axis, c in zip("xyz", sen.read_accel(veh)):
                    eb.log(tick, f"accel_{axis}_adc", str(c))
            eb.depth_code = None
        if tick % 20 == 0:
            track.append((t, veh.x, veh.y, veh.z, math.degrees(veh.psi) % 360.0, veh.u, veh.v,
                          veh.r, sen.depth_port_m(veh), port_clearance(veh)))
        if tick % 10 == 0:
            veh.slow_noise()
        if tick < n_ticks:
            vstep()
    if hasattr(prog, "log") and prog.log and prog.log[-1][1] is None:
        a, _, target = prog.log[-1]
        prog.log[-1] = (a, duration_s, target)
    return {"eb": eb, "veh": veh, "track": track, "start": (x0, y0, z0, h0), "true_start": true,
            "params": p, "sensors": sp, "program": prog}


def port_clearance(veh):
    """Distance from the port side (0.32 m off the centre line) to the wall on the port beam."""
    bearing = (math.degrees(veh.psi) - 90.0) % 360.0
    walls = {0.0: POOL["length_m"] - veh.x, 180.0: veh.x, 90.0: POOL["width_m"] - veh.y, 270.0: veh.y}
    best = min(walls, key=lambda n: abs(wrap180(bearing - n)))
    return walls[best] - 0.32


def derived(n, v):
    """Hidden effect `n` of size `v` in other units a scorer may want (ADC codes, degrees)."""
    lsb = SENSORS["adc_ref_v"] / SENSORS["adc_codes"]
    h_ut = SENSORS["field_ut"] * math.cos(math.radians(SENSORS["inclination_deg"]))
    if n == "water_current":
        return {"speed_mps": math.hypot(*v), "direction_deg": math.degrees(math.atan2(v[1], v[0])) % 360.0}
    if n == "compass_hard_iron":
        return {"horizontal_field_ut": h_ut,
                "peak_heading_error_deg": math.degrees(math.asin(min(1.0, math.hypot(*v) / h_ut)))}
    if n == "depth_emi":
        return {"lsb_rms_at_full_stern_duty": v / lsb}
    if n == "depth_offset":
        return {"offset_lsb": v * SENSORS["depth_gain_v_per_m"] / lsb}
    if n == "accel_offset":
        return {"offset_lsb": [x / lsb for x in v]}
    if n == "velocity_sensor_scale":
        return {"paddle_factor": 1.0 + v}
    if n == "depth_gain":
        return {"volts_per_m": SENSORS["depth_gain_v_per_m"] * (1.0 + v)}
    return {}


def hidden_truth(name, size):
    return {"name": name, "size": size, "default_size": EFFECTS[name][0], "unit": EFFECTS[name][1],
            "meaning": EFFECTS[name][2], "derived": derived(name, size)}


def write_run(out, args, effect, res, drawn=None):
    """Writes the measurement and truth.json. `drawn` says what was drawn beyond the noise:
    the structure's description, the start offset, the program's draw (all optional)."""
    drawn = drawn or {}
    os.makedirs(out, exist_ok=True)
    eb = res["eb"]
    x0, y0, z0, h0 = res["start"]
    name = f"independent-{args.program}-seed{args.seed}-{effect.name}"
    desc = (f"{VERSION}: program {args.program}, seed {args.seed}, hidden {effect.name}. "
            "Written by pty-tests/independent/mako_independent.py, not by eyebot-hil.")
    if drawn.get("structure") is not None:
        name += f"-structure{drawn['structure']['structure_seed']}"
    lines = [
        f"name = {json.dumps(name)}",
        f"description = {json.dumps(desc)}",
        f"duration_s = {args.duration:.1f}",
        'world = "worlds/pool.toml"',
        'sensors = "sensors/mako-2008.toml"',
        "",
        "[initial]",
        f"x_m = {x0:.3f}",
        f"y_m = {y0:.3f}",
        f"z_m = {z0:.3f}",
        f"heading_deg = {h0:.1f}",
        "roll_deg = 0.0",
        "pitch_deg = 0.0",
        "surge_mps = 0.0",
    ]
    if args.camera:
        lines += ["", "[camera]", f"position_std_m = {SENSORS['camera_std_m']}",
                  "speed_std_mps = 0.03"]
    with open(os.path.join(out, "experiment.toml"), "w", newline="\n") as f:
        f.write("\n".join(lines) + "\n")
    with open(os.path.join(out, "commands.csv"), "w", newline="\n") as f:
        f.write("t_s,port,starboard,bow,stern\n")
        for tick, c in eb.commands:
            f.write(f"{tick / TICKS_PER_S:.3f},{c[0]},{c[1]},{c[2]},{c[3]}\n")
    order = ["x_m", "y_m", "compass_deg", "depth_adc", "accel_x_adc", "accel_y_adc",
             "accel_z_adc", "paddle_speed_mps", "sonar1_m", "sonar2_m", "sonar3_m", "sonar4_m"]
    present = {c for row in eb.rows.values() for c in row}
    cols = [c for c in order if c in present]
    with open(os.path.join(out, "measured.csv"), "w", newline="\n") as f:
        f.write("t_s," + ",".join(cols) + "\n")
        for tick in sorted(eb.rows):
            row = eb.rows[tick]
            f.write(f"{tick / TICKS_PER_S:.3f}," + ",".join(row.get(c, "") for c in cols) + "\n")
    parts = [hidden_truth(n, v) for n, v in effect.parts]
    xt, yt, zt, ht = res["true_start"]
    truth = {
        "generator": VERSION,
        "program": args.program,
        "program_drawn": drawn.get("program"),
        "seed": args.seed,
        "duration_s": args.duration,
        "camera": args.camera,
        "hidden": parts[0] if len(parts) == 1 else {"name": effect.name, "effects": parts},
        "hidden_effects": parts,
        # the true initial state; `stated_start` is what experiment.toml says
        "start": {"x_m": xt, "y_m": yt, "z_m": zt, "heading_deg": ht},
        "stated_start": {"x_m": x0, "y_m": y0, "z_m": z0, "heading_deg": h0},
        "start_offset": drawn.get("start_offset"),
        "float_depth_m": float_depth_m(res["params"]),
        "structure": drawn.get("structure"),
        "wall_contacts": res["veh"].contacts,
        "vehicle": res["params"],
        "nominal_vehicle": NOMINAL,
        "sensors": res["sensors"],
        "pool": POOL,
    }
    with open(os.path.join(out, "truth.json"), "w", newline="\n") as f:
        json.dump(truth, f, indent=1, sort_keys=True)
        f.write("\n")


def summarise(program, res):
    """Summaries of the true track (0.1 s samples) to compare with the thesis."""
    tr, eb = res["track"], res["eb"]
    speeds = [math.hypot(s[5], s[6]) for s in tr]
    xs, ys, zs = [s[1] for s in tr], [s[2] for s in tr], [s[3] for s in tr]
    out = [f"top speed {max(speeds):.3f} m/s, mean {sum(speeds) / len(speeds):.3f} m/s; "
           f"x {min(xs):.2f}..{max(xs):.2f} m, y {min(ys):.2f}..{max(ys):.2f} m, "
           f"CoM depth {min(zs):.2f}..{max(zs):.2f} m; wall contacts {res['veh'].contacts}; "
           f"{len(eb.commands)} command rows, {len(eb.rows)} measured rows"]
    # spins: segments of steady turning
    seg, segs = [], []
    for s in tr:
        if abs(s[7]) > 0.08:
            seg.append(s)
        elif seg:
            segs.append(seg)
            seg = []
    if seg:
        segs.append(seg)
    for seg in segs:
        unwrapped, prev = [0.0], seg[0][4]
        for s in seg[1:]:
            unwrapped.append(unwrapped[-1] + wrap180(s[4] - prev))
            prev = s[4]
        turns = abs(unwrapped[-1]) / 360.0
        if turns < 1.0:
            continue
        # the first full turn that starts 5 s into the spin (spun up): period and circle
        k0 = next(i for i, q in enumerate(seg) if q[0] >= seg[0][0] + 5.0)
        ends = [i for i, h in enumerate(unwrapped) if abs(h - unwrapped[k0]) >= 360.0]
        label = "one turn after spin-up"
        if ends:
            last = seg[k0:ends[0] + 1]
        else:  # a single turn: the last full turn, spin-up included
            label = "last full turn"
            k = max(i for i, h in enumerate(unwrapped) if abs(unwrapped[-1] - h) >= 360.0)
            last = seg[k:]
        period = last[-1][0] - last[0][0]
        dia = 0.5 * ((max(q[1] for q in last) - min(q[1] for q in last))
                     + (max(q[2] for q in last) - min(q[2] for q in last)))
        way = "clockwise" if unwrapped[-1] > 0 else "anticlockwise"
        out.append(f"spin {way} at t={seg[0][0]:.0f} s: {turns:.1f} turns, {label} {period:.1f} s, "
                   f"circle {dia:.2f} m across")
    # depth hold: the sensor-port depth over the last 8 s of each constant-target stretch
    prog = res["program"]
    if isinstance(prog, (DepthHold, Mixed)):
        for a, b, target in prog.log:
            vals = [s[8] for s in tr if b - 8.0 <= s[0] < b]
            if len(vals) > 10:
                m = sum(vals) / len(vals)
                sd = math.sqrt(sum((v - m) ** 2 for v in vals) / len(vals))
                what = "floating, motors off" if target == 0.0 else f"depth target {target:.2f} m"
                out.append(f"{what} ({a:.0f}-{b:.0f} s): sensor port at "
                           f"{m:.3f} +- {sd:.3f} m over the last 8 s")
    if isinstance(prog, WallRun):
        d = [s[9] for s in tr if s[0] > 10.0 and abs(s[7]) < 0.05]
        d.sort()
        if d:
            out.append(f"wall run: port side to the nearest wall, straight running: median "
                       f"{d[len(d) // 2]:.2f} m, 10-90 % {d[len(d) // 10]:.2f}..{d[9 * len(d) // 10]:.2f} m "
                       f"(target 1.0 m from the port-fore transducer); corners turned {prog.corners}")
    return out


def quiet(p):
    """`p` without process noise or rpm fluctuation, for open-loop checks."""
    p = json.loads(json.dumps(p))
    for k in ("rpm_fluctuation_rel", "dist_surge_n", "dist_sway_n", "dist_yaw_nm", "dist_heave_n"):
        p[k] = 0.0
    return p


def plausibility(p):
    """What makes a drawn vehicle a plausible Mako, measured open loop without noise in open
    water: top speed after 40 s at 100/100 %; seconds for one spot turn at +-100 % each way
    (after 10 s of spin-up; None when it does not turn 360 deg within 60 s); the centre of
    mass's depth, heave speed, pitch and roll 60 s after release at 1 m, motors off."""
    p = quiet(p)

    def fresh(z=None):
        v = Vehicle(p, 0, 12.5, 6.25, 0.0, float_depth_m(p) if z is None else z, [0.0, 0.0])
        v.walls = False
        return v

    veh = fresh()
    veh.command([100, 100, 0, 0])
    for _ in range(40 * TICKS_PER_S):
        veh.step()
    out = {"top_speed_mps": math.hypot(veh.u, veh.v)}
    for name, cmd in (("spot_turn_clockwise_s", [100, -100, 0, 0]),
                      ("spot_turn_anticlockwise_s", [-100, 100, 0, 0])):
        veh = fresh()
        veh.command(cmd)
        for _ in range(10 * TICKS_PER_S):
            veh.step()
        psi0, n = veh.psi, 0
        while abs(veh.psi - psi0) < 2.0 * math.pi and n < 60 * TICKS_PER_S:
            veh.step()
            n += 1
        out[name] = n * DT_S if abs(veh.psi - psi0) >= 2.0 * math.pi else None
    veh = fresh(1.0)
    for _ in range(60 * TICKS_PER_S):
        veh.step()
    out["depth_after_release_m"], out["heave_after_release_mps"] = veh.z, veh.w
    out["pitch_at_rest_deg"], out["roll_at_rest_deg"] = math.degrees(veh.theta), math.degrees(veh.phi)
    out["float_depth_m"] = float_depth_m(p)
    return out


def check_family(count):
    """The range of every `plausibility` figure over structure seeds 0..count-1."""
    rows = [plausibility(draw_structure(n)[0]) for n in range(count)]
    nominal = plausibility(NOMINAL)
    lines = [f"{count} vehicles drawn (structure seeds 0..{count - 1}), open loop, no noise:"]
    for key in rows[0]:
        vals = [r[key] for r in rows]
        done = [v for v in vals if v is not None]
        missing = len(vals) - len(done)
        lines.append(f"{key}: {min(done):.3f} .. {max(done):.3f}"
                     + (f" ({missing} without a value)" if missing else "")
                     + f"; nominal {nominal[key]:.3f}")
    return lines


def manoeuvres(effect, base=None):
    """Open-loop checks against thesis 4.5-4.7, on the true vehicle without sensors or noise;
    `base` is a drawn structure's parameters (None: NOMINAL)."""
    p = quiet(effect.vehicle_params(NOMINAL if base is None else base))
    z_start = 0.238 if base is None else float_depth_m(p)
    lines = []

    def fresh(heading=0.0):
        v = Vehicle(p, 0, 12.5, 6.25, heading, z_start, effect.current)
        v.walls = False  # open water: the straight run and coast-down need ~25 m
        return v

    veh = fresh()
    veh.command([100, 100, 0, 0])
    t95 = None
    amax = 0.0
    for i in range(40 * TICKS_PER_S):
        veh.step()
        amax = max(amax, veh.du)
        if t95 is None and veh.u >= 0.95 * 0.44:
            t95 = (i + 1) * DT_S
    top = math.hypot(veh.u, veh.v)
    lines.append(f"straight, 100/100 %: top speed {top:.3f} m/s (thesis 0.44), "
                 f"0.95 x 0.44 m/s reached after {t95 if t95 is None else round(t95, 1)} s "
                 f"(thesis ~6 s to top speed), max acceleration {100 * amax:.1f} cm/s^2 (thesis <= 9.5), "
                 f"heading drift {math.degrees(veh.psi):.0f} deg in 40 s")
    veh.command([0, 0, 0, 0])
    t_stop = {}
    for i in range(120 * TICKS_PER_S):
        veh.step()
        for lim in (0.02, 0.01, 0.005):
            if lim not in t_stop and veh.u < lim:
                t_stop[lim] = (i + 1) * DT_S
    lines.append("coast-down from top speed to " + ", ".join(
        f"{k} m/s: {v:.1f} s" for k, v in sorted(t_stop.items(), reverse=True)) + " (thesis ~32 s to rest)")
    for name, cmd in (("clockwise (port +100, starboard -100)", [100, -100, 0, 0]),
                      ("anticlockwise (port -100, starboard +100)", [-100, 100, 0, 0]),
                      ("clockwise at 60 %", [60, -60, 0, 0])):
        veh = fresh()
        veh.command(cmd)
        for _ in range(30 * TICKS_PER_S):
            veh.step()
        psi0, xs, ys, n = veh.psi, [], [], 0
        while abs(veh.psi - psi0) < 2.0 * math.pi and n < 200 * TICKS_PER_S:
            veh.step()
            n += 1
            xs.append(veh.x)
            ys.append(veh.y)
        dia = 0.5 * ((max(xs) - min(xs)) + (max(ys) - min(ys)))
        lines.append(f"spot turn {name}: one turn {n * DT_S:.1f} s, circle {dia:.2f} m across, "
                     f"speed {math.hypot(veh.u, veh.v):.3f} m/s, sway {veh.v:+.3f} m/s "
                     "(thesis 23.17 / 23.5 s, 0.8 m)")
    lo, hi = 0.0, 100.0
    for _ in range(30):
        mid = 0.5 * (lo + hi)
        veh = fresh()
        veh.command([0, 0, mid, mid])
        veh.n = list(veh.n_ss)
        net = sum(veh.thrusts()[2:]) - p["reserve_buoyancy_n"]
        lo, hi = (mid, hi) if net < 0.0 else (lo, mid)
    lines.append(f"bow = stern = {lo:.0f} % balances the {p['reserve_buoyancy_n']:.3g} N reserve buoyancy")
    veh = fresh()
    veh.z = 1.0
    veh.command([0, 0, 100, 100])
    for _ in range(10 * TICKS_PER_S):
        veh.step()
    lines.append(f"bow = stern = 100 %: sinks at {veh.w:.3f} m/s; pitch {math.degrees(veh.theta):+.1f} deg")
    return lines


def parse_size(name, text):
    default = EFFECTS[name][0]
    if text is None:
        return default
    if name == "none":
        raise SystemExit("error: --size: the effect `none` takes no size")
    try:
        vals = [float(v) for v in text.split(",")]
    except ValueError:
        raise SystemExit(f"error: --size: expected a number or comma-separated numbers, found `{text}`")
    if any(not math.isfinite(v) for v in vals):
        raise SystemExit(f"error: --size: expected finite numbers, found `{text}`")
    if isinstance(default, list):
        if len(vals) != len(default):
            raise SystemExit(f"error: --size: `{name}` expects {len(default)} comma-separated "
                             f"values ({EFFECTS[name][1]}), found {len(vals)}")
        return vals
    if len(vals) != 1:
        raise SystemExit(f"error: --size: `{name}` expects one value ({EFFECTS[name][1]}), found {len(vals)}")
    v = vals[0]
    if name in ("drag", "yaw_damping") and v <= 0.0:
        raise SystemExit(f"error: --size: `{name}` is a scale and must be > 0, found {v}")
    if name in ("compass_latency", "thruster_lag", "depth_emi") and v < 0.0:
        raise SystemExit(f"error: --size: `{name}` must be >= 0 ({EFFECTS[name][1]}), found {v}")
    if name == "thrust_gain" and v <= -1.0:
        raise SystemExit(f"error: --size: `thrust_gain` must be > -1 (relative), found {v}")
    return v


def parse_hidden(hidden, size):
    """`--hidden A` or `--hidden A+B` with `--size SA` or `--size SA;SB` (`-` in a place: that
    effect's default size) -> Effects."""
    names = hidden.split("+")
    for n in names:
        if n not in EFFECTS:
            raise SystemExit(f"error: --hidden: expected one of {', '.join(EFFECTS)}, or two of "
                             f"them joined by `+`; found `{hidden}`")
    if len(names) > 1:
        if len(names) != 2 or names[0] == names[1] or "none" in names:
            raise SystemExit(f"error: --hidden: expected two different effects other than `none` "
                             f"joined by `+` (A+B); found `{hidden}`")
    sizes = [None] * len(names) if size is None else size.split(";")
    if len(sizes) != len(names):
        raise SystemExit(f"error: --size: `{hidden}` takes {len(names)} sizes separated by `;` "
                         f"(`-` for a default), found {len(sizes)} in `{size}`")
    parts = [(n, parse_size(n, None if t is None or (len(names) > 1 and t.strip() == "-") else t))
             for n, t in zip(names, sizes)]
    return Effects.several(parts)


def parse_start_offset(text):
    """`--start-offset NORTH,EAST,DOWN,HEADING` (m, m, m, deg) within START_OFFSET_LIMITS."""
    horizontal, depth, heading = START_OFFSET_LIMITS
    want = (f"four comma-separated numbers NORTH_M,EAST_M,DOWN_M,HEADING_DEG with at most "
            f"{horizontal} m horizontally, {depth} m in depth and {heading} deg, or `random`")
    try:
        vals = [float(v) for v in text.split(",")]
    except ValueError:
        raise SystemExit(f"error: --start-offset: expected {want}; found `{text}`")
    if len(vals) != 4 or not all(math.isfinite(v) for v in vals):
        raise SystemExit(f"error: --start-offset: expected {want}; found `{text}`")
    if (math.hypot(vals[0], vals[1]) > horizontal + 1e-12 or abs(vals[2]) > depth
            or abs(vals[3]) > heading):
        raise SystemExit(f"error: --start-offset: expected {want}; found `{text}`")
    return vals


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--program", choices=sorted(PROGRAM_CLASSES) + ["random"],
                    help="the EyeBot control program; `random`: drawn per run from the seed "
                         "and, when given, the structure seed")
    ap.add_argument("--seed", type=int, default=1, help="random seed (integer)")
    ap.add_argument("--structure-seed", type=int, default=None,
                    help="draw the vehicle's structure from the family (see --list); absent: "
                         "the nominal vehicle")
    ap.add_argument("--start-offset", default=None,
                    help="true start minus stated start: NORTH_M,EAST_M,DOWN_M,HEADING_DEG, or "
                         "`random`; drawn by default with --structure-seed (0,0,0,0 for none)")
    ap.add_argument("--duration", type=float, default=180.0, help="run length in seconds (10..1800)")
    ap.add_argument("--hidden", default="none", help="hidden effect, or two as A+B (see --list)")
    ap.add_argument("--size", default=None,
                    help="effect size in the effect's unit (see --list); two effects: SA;SB")
    ap.add_argument("--camera", dest="camera", action="store_true", default=True,
                    help="write the overhead-camera track x_m, y_m (default)")
    ap.add_argument("--no-camera", dest="camera", action="store_false", help="no camera track")
    ap.add_argument("--out", help="measurement directory to write")
    ap.add_argument("--list", action="store_true",
                    help="list programs, effects and the structure family, then exit")
    ap.add_argument("--summary", action="store_true", help="print a summary of the true track")
    ap.add_argument("--manoeuvres", action="store_true",
                    help="print open-loop checks (top speed, coast-down, spot turns) and exit")
    ap.add_argument("--check-family", type=int, default=None, metavar="COUNT",
                    help="print the range of the plausibility checks over structure seeds "
                         "0..COUNT-1, then exit")
    args = ap.parse_args(argv)
    if args.check_family is not None:
        if args.check_family < 1:
            ap.error(f"--check-family: expected a count >= 1, found {args.check_family}")
        for line in check_family(args.check_family):
            print(line)
        return 0
    if args.list:
        print("programs:")
        for k in sorted(PROGRAMS):
            print(f"  {k:22s} {PROGRAMS[k]}")
        print("hidden effects (default size, unit):")
        for k, (d, unit, what) in EFFECTS.items():
            ds = "-" if d is None else (",".join(f"{v:g}" for v in d) if isinstance(d, list) else f"{d:g}")
            print(f"  {k:22s} {ds:>12s} {unit:38s} {what}")
        # unindented lines: readers of the effect lines above take indented lines only
        print("structure family (--structure-seed N; absent: the nominal vehicle):")
        for part, what, why in STRUCTURE_FAMILY:
            print(f"- {part}: {what}. Why: {why}.")
        return 0
    structure = None if args.structure_seed is None else draw_structure(args.structure_seed)
    if args.manoeuvres:
        effect = parse_hidden(args.hidden, args.size)
        for line in manoeuvres(effect, None if structure is None else structure[0]):
            print(line)
        return 0
    if args.program is None:
        ap.error("--program: expected one of " + ", ".join(sorted(PROGRAM_CLASSES) + ["random"]))
    if args.out is None:
        ap.error("--out: expected the measurement directory to write")
    if not (10.0 <= args.duration <= 1800.0):
        ap.error(f"--duration: expected seconds in 10..1800, found {args.duration}")
    effect = parse_hidden(args.hidden, args.size)
    drawn = {}
    # the programme and the start are drawn per run: from the seed, and from the structure
    # seed too when there is one (one vehicle, many runs that each start differently)
    per_run = f"{args.seed}" if structure is None else f"structure/{args.structure_seed}/{args.seed}"
    if args.program == "random":
        args.program = random.Random(f"{per_run}/program kind").choice(sorted(PROGRAM_CLASSES))
        drawn["program"] = {"argument": "random", "from": sorted(PROGRAM_CLASSES),
                            "stream": f"{per_run}/program kind"}
    offset = None
    if args.start_offset is not None and args.start_offset != "random":
        offset = parse_start_offset(args.start_offset)
    elif args.start_offset == "random" or structure is not None:
        shift = 0.0 if structure is None else float_depth_m(structure[0]) - float_depth_m(NOMINAL)
        offset = draw_start_offset(random.Random(f"{per_run}/start offset"), shift)
    if offset is not None:
        drawn["start_offset"] = {"north_m": offset[0], "east_m": offset[1], "down_m": offset[2],
                                 "heading_deg": offset[3]}
    if structure is not None:
        drawn["structure"] = structure[2]
    t0 = time.perf_counter()
    res = simulate(args.program, args.seed, args.duration, effect, args.camera,
                   None if structure is None else structure[:2], offset)
    write_run(args.out, args, effect, res, drawn)
    if args.summary:
        for line in summarise(args.program, res):
            print(line)
        print(f"wall time {time.perf_counter() - t0:.2f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
