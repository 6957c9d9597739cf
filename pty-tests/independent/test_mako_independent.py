"""Checks of the independent model: run with `python3 -m unittest` in this directory."""

import csv
import filecmp
import hashlib
import json
import math
import os
import subprocess
import sys
import tempfile
import unittest

HERE = os.path.dirname(os.path.abspath(__file__))
PROGRAM = os.path.join(HERE, "mako_independent.py")
sys.dont_write_bytecode = True  # leave no __pycache__ in the tree
sys.path.insert(0, HERE)
import mako_independent as model  # noqa: E402


def run(out, *args):
    subprocess.run([sys.executable, PROGRAM, "--out", out, *args], check=True,
                   stdout=subprocess.DEVNULL)


def read(d, name):
    with open(os.path.join(d, name)) as f:
        return f.read()


def truth(d):
    return json.loads(read(d, "truth.json"))


# The pinned output of the nominal vehicle (no --structure-seed): runs and the first 16 hex
# digits of the sha256 of experiment.toml, commands.csv, measured.csv and truth.json. The
# truth.json hash leaves out the keys that describe draws (DRAW_TRUTH_KEYS): the rest is
# written again the way the program writes it and hashed.
NOMINAL_RUNS = [
    ("mixed", 7301, 180, "none", None, ['cb11995e3933b10d', 'b47e9e2b9d838724', 'acbee1da617bcc0a', '17d89ee463c7c65f']),
    ("mixed", 9, 60, "compass_latency", None, ['52607c793857bc88', '98350234cf2d8446', 'f096c01353dc92af', 'fd35cfc9bae8f00f']),
    ("mixed", 4, 60, "thruster_lag", '0.5', ['40dc42786b6eda87', '27a2db8477a19b62', '3cabf3d397f1c2be', '187f1fce9dc0ebfc']),
    ("mixed", 4, 60, "drag", None, ['b30dc160dc547c78', '4811c76bef7bda6a', '65e06b82f758567c', 'c85ecd1498bff1e0']),
    ("depth_hold", 4, 60, "depth_emi", None, ['53128e53e83c6ec3', '78a4e359722b439d', '645f73b6ab235d78', '82e474e57f961fde']),
    ("heading_hold", 3, 40, "water_current", '0.03,-0.01', ['dca787d27e539a3a', '6cbac27aa2909a2f', '3d767a3498c473f1', '842fad2a5a7a4ffa']),
    ("spins", 3, 40, "thruster_imbalance", None, ['2d295ee50ad504d8', '32dbc42e89666c64', 'fae226a2d30903e3', '34057759b2eabe80']),
    ("square", 3, 40, "yaw_damping", None, ['a5dce5f3fa8542a5', '98823d684ecb1db7', '525ee3b998fd6778', 'be077a71bb7ed267']),
    ("wall_run", 3, 40, "none", None, ['3d0684cfd4b11813', '21a2b414b102ac82', '3ab5de72e7df917a', 'd08e1190dc8f2221']),
]
DRAW_TRUTH_KEYS = {"float_depth_m", "hidden_effects", "program_drawn", "stated_start", "start_offset",
                  "structure"}


def sha(text):
    return hashlib.sha256(text.encode()).hexdigest()[:16]


class NominalVehicle(unittest.TestCase):
    def test_output_without_a_structure_seed_matches_the_pinned_hashes(self):
        with tempfile.TemporaryDirectory() as tmp:
            for prog, seed, duration, hidden, size, want in NOMINAL_RUNS:
                d = os.path.join(tmp, f"{prog}-{seed}-{hidden}")
                args = ["--program", prog, "--seed", str(seed), "--duration", str(duration),
                        "--hidden", hidden] + (["--size", size] if size else [])
                run(d, *args)
                got = [sha(read(d, n)) for n in ("experiment.toml", "commands.csv", "measured.csv")]
                old = {k: v for k, v in truth(d).items() if k not in DRAW_TRUTH_KEYS}
                got.append(sha(json.dumps(old, indent=1, sort_keys=True) + "\n"))
                self.assertEqual(got, want, d)

    def test_nominal_truth_states_the_float_depth_and_an_untouched_start(self):
        with tempfile.TemporaryDirectory() as tmp:
            run(tmp + "/a", "--program", "spins", "--seed", "2", "--duration", "10")
            t = truth(tmp + "/a")
            self.assertAlmostEqual(t["float_depth_m"], 0.2383, places=4)
            self.assertEqual(t["start"], t["stated_start"])
            self.assertIsNone(t["structure"])
            self.assertIsNone(t["start_offset"])


class StructureFamily(unittest.TestCase):
    def test_same_arguments_same_bytes_with_everything_drawn(self):
        with tempfile.TemporaryDirectory() as tmp:
            a, b = os.path.join(tmp, "a"), os.path.join(tmp, "b")
            for d in (a, b):
                run(d, "--program", "random", "--seed", "9", "--structure-seed", "5",
                    "--duration", "60", "--hidden", "compass_latency+thrust_gain")
            for name in ("experiment.toml", "commands.csv", "measured.csv", "truth.json"):
                self.assertTrue(filecmp.cmp(os.path.join(a, name), os.path.join(b, name),
                                            shallow=False), name)

    def test_structure_seeds_draw_different_structures(self):
        drawn = [model.draw_structure(n) for n in range(20)]
        params = [json.dumps(p, sort_keys=True) for p, _, _ in drawn]
        self.assertEqual(len(set(params)), 20)
        sensors = [json.dumps(sp, sort_keys=True) for _, sp, _ in drawn]
        self.assertEqual(len(set(sensors)), 20)
        kinds = [k for _, _, k in drawn]
        self.assertGreaterEqual(len({k["surge_drag_law"] for k in kinds}), 3)
        self.assertEqual({k["munk_moment"] for k in kinds}, {True, False})
        self.assertEqual({k["sway_yaw_cross_damping"]["n_v"] for k in kinds},
                         {"off", "positive", "negative"})
        self.assertEqual({k["surge_drag_grows_with_sway"] for k in kinds}, {True, False})
        # the same structure seed draws the same vehicle whatever the noise seed
        self.assertEqual(model.draw_structure(3), model.draw_structure(3))
        with tempfile.TemporaryDirectory() as tmp:
            for name, structure, seed in (("s1", "1", "4"), ("s2", "2", "4"), ("s1b", "1", "5")):
                run(os.path.join(tmp, name), "--program", "mixed", "--seed", seed,
                    "--structure-seed", structure, "--duration", "30", "--start-offset", "0,0,0,0")
            s1, s2, s1b = (truth(os.path.join(tmp, n)) for n in ("s1", "s2", "s1b"))
            self.assertNotEqual(s1["vehicle"], s2["vehicle"])
            self.assertNotEqual(s1["vehicle"], s1["nominal_vehicle"])
            self.assertEqual(s1["vehicle"], s1b["vehicle"])
            self.assertEqual(s1["structure"]["structure_seed"], 1)
            self.assertNotEqual(read(os.path.join(tmp, "s1"), "measured.csv"),
                                read(os.path.join(tmp, "s2"), "measured.csv"))

    def test_every_drawn_vehicle_is_a_plausible_mako(self):
        """Top speed within 30 % of 0.44 m/s, a spot turn each way within 60 s, and it floats:
        released at 1 m with the motors off it rests at its float depth, the hull's top out."""
        for n in range(40):
            p, _, _ = model.draw_structure(n)
            got = model.plausibility(p)
            with self.subTest(structure_seed=n, got=got):
                self.assertTrue(0.7 * 0.44 <= got["top_speed_mps"] <= 1.3 * 0.44)
                self.assertIsNotNone(got["spot_turn_clockwise_s"])
                self.assertIsNotNone(got["spot_turn_anticlockwise_s"])
                self.assertTrue(0.0 < got["float_depth_m"] < p["top_above_com_m"])
                self.assertAlmostEqual(got["depth_after_release_m"], got["float_depth_m"], delta=0.005)
                self.assertLess(abs(got["heave_after_release_mps"]), 0.001)

    def test_the_true_start_is_off_the_stated_one_and_truth_says_by_how_much(self):
        with tempfile.TemporaryDirectory() as tmp:
            run(tmp + "/drawn", "--program", "depth_hold", "--seed", "6", "--structure-seed", "8",
                "--duration", "20")
            run(tmp + "/none", "--program", "depth_hold", "--seed", "6", "--structure-seed", "8",
                "--duration", "20", "--start-offset", "0,0,0,0")
            run(tmp + "/given", "--program", "depth_hold", "--seed", "6", "--duration", "20",
                "--start-offset", "0.1,-0.2,0.3,-15")
            for name in ("drawn", "none", "given"):
                self.assertEqual(read(tmp + "/" + name, "experiment.toml").count("z_m = 0.238"), 1, name)
            t = truth(tmp + "/drawn")
            off, true, stated = t["start_offset"], t["start"], t["stated_start"]
            self.assertLessEqual(math.hypot(off["north_m"], off["east_m"]), 0.3)
            self.assertLessEqual(abs(off["down_m"]), 0.3)
            # released under water or bobbing at the surface, not dropped in from the air
            self.assertTrue(-0.03 <= true["z_m"] - t["float_depth_m"] <= 0.26, true)
            self.assertLessEqual(abs(off["heading_deg"]), 20.0)
            self.assertGreater(abs(off["down_m"]) + abs(off["heading_deg"]), 0.0)
            self.assertAlmostEqual(true["x_m"] - stated["x_m"], off["north_m"])
            self.assertAlmostEqual(true["z_m"] - stated["z_m"], off["down_m"])
            self.assertAlmostEqual(model.wrap180(true["heading_deg"] - stated["heading_deg"]),
                                   off["heading_deg"])
            self.assertAlmostEqual(t["float_depth_m"], t["structure"]["float_depth_m"])
            self.assertEqual(t["float_depth_m"], model.float_depth_m(t["vehicle"]))
            self.assertNotEqual(read(tmp + "/drawn", "measured.csv"),
                                read(tmp + "/none", "measured.csv"))
            g = truth(tmp + "/given")
            self.assertEqual([g["start_offset"][k] for k in ("north_m", "east_m", "down_m", "heading_deg")],
                             [0.1, -0.2, 0.3, -15.0])
            self.assertAlmostEqual(g["start"]["z_m"], g["stated_start"]["z_m"] + 0.3)
            self.assertIsNone(g["structure"])

    def test_vehicle_effects_act_on_every_term_of_a_drawn_vehicle(self):
        base = next(p for p, _, k in map(model.draw_structure, range(50))
                    if k["surge_drag_grows_with_sway"] and k["sway_drag_cubic"] and k["yaw_damping_cubic"])
        p = model.Effects.several([("thruster_lag", 0.5), ("drag", 2.0)]).vehicle_params(base)
        for m, m0 in zip(p["thruster_maps"], base["thruster_maps"]):
            self.assertAlmostEqual(m["tau_spin_up_s"], m0["tau_spin_up_s"] + 0.5)
            self.assertAlmostEqual(m["tau_spin_down_s"], m0["tau_spin_down_s"] + 0.5)
        for k in ("surge_lin", "surge_quad", "surge_cubic", "surge_per_sway", "sway_lin",
                  "sway_quad", "sway_cubic"):
            self.assertAlmostEqual(p[k], 2.0 * base[k], msg=k)
        q = model.Effects("yaw_damping", 1.5).vehicle_params(base)
        self.assertAlmostEqual(q["yaw_cubic"], 1.5 * base["yaw_cubic"])

    def test_one_vehicle_starts_each_run_differently(self):
        with tempfile.TemporaryDirectory() as tmp:
            for seed in ("6", "7"):
                run(os.path.join(tmp, seed), "--program", "spins", "--seed", seed,
                    "--structure-seed", "8", "--duration", "10")
            a, b = truth(os.path.join(tmp, "6")), truth(os.path.join(tmp, "7"))
            self.assertEqual(a["vehicle"], b["vehicle"])
            self.assertNotEqual(a["start_offset"], b["start_offset"])

    def test_readme_describes_every_part_of_the_family(self):
        with open(os.path.join(HERE, "README.md")) as f:
            text = f.read()
        for part, _, _ in model.STRUCTURE_FAMILY:
            self.assertIn(f"| {part} |", text)

    def test_random_program_draws_several_kinds_and_truth_names_it(self):
        seen = set()
        with tempfile.TemporaryDirectory() as tmp:
            for seed in range(12):
                d = os.path.join(tmp, str(seed))
                run(d, "--program", "random", "--seed", str(seed), "--duration", "10")
                t = truth(d)
                self.assertIn(t["program"], model.PROGRAM_CLASSES)
                self.assertEqual(t["program_drawn"]["argument"], "random")
                self.assertIn(f"independent-{t['program']}-seed{seed}-",
                              read(d, "experiment.toml"))
                seen.add(t["program"])
        self.assertGreaterEqual(len(seen), 4, seen)


class TwoEffects(unittest.TestCase):
    def test_two_effects_differ_from_each_alone_and_truth_records_both(self):
        with tempfile.TemporaryDirectory() as tmp:
            data = {}
            for hidden in ("none", "compass_latency", "thrust_gain", "compass_latency+thrust_gain"):
                d = os.path.join(tmp, hidden)
                run(d, "--program", "mixed", "--seed", "4", "--duration", "60", "--hidden", hidden)
                data[hidden] = read(d, "measured.csv")
            self.assertEqual(len(set(data.values())), 4)
            t = truth(os.path.join(tmp, "compass_latency+thrust_gain"))
            self.assertEqual([(h["name"], h["size"]) for h in t["hidden_effects"]],
                             [("compass_latency", 0.4), ("thrust_gain", -0.2)])
            self.assertEqual(t["hidden"]["name"], "compass_latency+thrust_gain")
            self.assertAlmostEqual(t["vehicle"]["thrust_fwd_n"], 1.68 * 0.8)

    def test_sizes_of_two_effects_are_separated_by_a_semicolon(self):
        e = model.Effects.several([("thruster_lag", 0.5), ("drag", 1.2)])
        p = e.vehicle_params(model.NOMINAL)
        self.assertAlmostEqual(p["tau_spin_up_s"], 0.85)
        self.assertAlmostEqual(p["surge_lin"], 4.2 * 1.2)
        with tempfile.TemporaryDirectory() as tmp:
            run(tmp + "/a", "--program", "spins", "--seed", "1", "--duration", "10",
                "--hidden", "water_current+compass_offset", "--size", "0.01,0.02;-")
            t = truth(tmp + "/a")
            self.assertEqual([h["size"] for h in t["hidden_effects"]], [[0.01, 0.02], 6.0])

    def test_bad_two_effect_and_start_arguments_name_the_argument(self):
        for args, word in ((["--hidden", "drag+drag"], "--hidden"),
                           (["--hidden", "none+drag"], "--hidden"),
                           (["--hidden", "drag+bogus"], "--hidden"),
                           (["--hidden", "drag+thrust_gain+thruster_lag"], "--hidden"),
                           (["--hidden", "drag+thrust_gain", "--size", "1.2"], "--size"),
                           (["--hidden", "drag+thrust_gain", "--size", "1.2;x"], "--size"),
                           (["--start-offset", "0.5,0,0,0"], "--start-offset"),
                           (["--start-offset", "0,0,0,25"], "--start-offset"),
                           (["--start-offset", "0,0,0"], "--start-offset"),
                           (["--structure-seed", "x"], "--structure-seed")):
            p = subprocess.run([sys.executable, PROGRAM, "--program", "spins", "--out",
                                os.devnull + "-x", *args], capture_output=True, text=True)
            self.assertNotEqual(p.returncode, 0, args)
            self.assertIn(word, p.stderr, args)


class ListFormat(unittest.TestCase):
    def test_effect_lines_still_read_as_the_benchmark_reads_them(self):
        """The Rust benchmark (`default_sizes` in src/gap/bench/independent.rs) reads every
        indented line after `hidden effects` as a name and a size (`-` or numbers)."""
        text = subprocess.run([sys.executable, PROGRAM, "--list"], capture_output=True, text=True,
                              check=True).stdout
        sizes, in_effects = {}, False
        for line in text.splitlines():
            if line.startswith("hidden effects"):
                in_effects = True
                continue
            if not in_effects or not line.startswith(" "):
                continue
            name, size = line.split()[:2]
            if size != "-":
                sizes[name] = [float(v) for v in size.split(",")]
        want = {k: (d if isinstance(d, list) else [d]) for k, (d, _, _) in model.EFFECTS.items()
                if d is not None}
        self.assertEqual(sizes, want)
        family = text.split("structure family")[1]
        for part, _, _ in model.STRUCTURE_FAMILY:
            self.assertIn(f"\n- {part}: ", family)


class Format(unittest.TestCase):
    def test_every_program_writes_the_documented_files(self):
        with tempfile.TemporaryDirectory() as tmp:
            for prog in sorted(model.PROGRAM_CLASSES):
                d = os.path.join(tmp, prog)
                run(d, "--program", prog, "--seed", "3", "--duration", "40")
                with open(os.path.join(d, "commands.csv")) as f:
                    rows = list(csv.reader(f))
                self.assertEqual(rows[0], ["t_s", "port", "starboard", "bow", "stern"])
                times = [float(r[0]) for r in rows[1:]]
                self.assertEqual(times, sorted(times))
                self.assertTrue(0.0 <= times[0] and times[-1] <= 40.0)
                for r in rows[1:]:
                    self.assertTrue(all(-100 <= int(v) <= 100 for v in r[1:]), r)
                with open(os.path.join(d, "measured.csv")) as f:
                    rows = list(csv.reader(f))
                self.assertEqual(rows[0][0], "t_s")
                known = {"x_m", "y_m", "compass_deg", "depth_adc", "accel_x_adc", "accel_y_adc",
                         "accel_z_adc", "paddle_speed_mps", "sonar1_m", "sonar2_m", "sonar3_m",
                         "sonar4_m"}
                self.assertTrue(set(rows[0][1:]) <= known, rows[0])
                self.assertTrue(all(len(r) == len(rows[0]) for r in rows))
                col = rows[0].index("compass_deg")
                headings = [int(r[col]) for r in rows[1:] if r[col]]
                self.assertTrue(headings and all(0 <= h <= 359 for h in headings))
                col = rows[0].index("depth_adc")
                self.assertTrue(all(0 <= int(r[col]) <= 1023 for r in rows[1:] if r[col]))
                with open(os.path.join(d, "truth.json")) as f:
                    truth = json.load(f)
                self.assertEqual(truth["program"], prog)
                self.assertEqual(truth["hidden"]["name"], "none")

    def test_same_arguments_same_bytes(self):
        with tempfile.TemporaryDirectory() as tmp:
            a, b = os.path.join(tmp, "a"), os.path.join(tmp, "b")
            for d in (a, b):
                run(d, "--program", "mixed", "--seed", "9", "--duration", "60",
                    "--hidden", "compass_latency")
            for name in ("experiment.toml", "commands.csv", "measured.csv", "truth.json"):
                self.assertTrue(filecmp.cmp(os.path.join(a, name), os.path.join(b, name),
                                            shallow=False), name)


class Effects(unittest.TestCase):
    def test_every_effect_changes_the_data_of_a_program_that_sees_it(self):
        with tempfile.TemporaryDirectory() as tmp:
            base = {}
            for prog in ("mixed", "depth_hold"):
                d = os.path.join(tmp, prog + "-none")
                run(d, "--program", prog, "--seed", "4", "--duration", "60")
                with open(os.path.join(d, "measured.csv")) as f:
                    base[prog] = f.read()
            for name in model.EFFECTS:
                if name == "none":
                    continue
                prog = "depth_hold" if name == "depth_emi" else "mixed"
                d = os.path.join(tmp, prog + "-" + name)
                run(d, "--program", prog, "--seed", "4", "--duration", "60", "--hidden", name)
                with open(os.path.join(d, "measured.csv")) as f:
                    self.assertNotEqual(f.read(), base[prog], name)

    def test_a_hull_moving_with_the_water_keeps_moving_with_it_as_it_turns(self):
        # A steady, uniform current carries a hull with no water-relative velocity and no
        # thrust along with it whatever the hull's yaw rate: the forces act on the relative
        # velocity, which stays zero, and the ground velocity is the current's.
        p = dict(model.NOMINAL)
        for k in ("dist_surge_n", "dist_sway_n", "dist_yaw_nm", "dist_heave_n"):
            p[k] = 0.0
        current = [0.05, -0.02]
        for rate in (0.0, 0.5, -1.0):
            veh = model.Vehicle(p, 1, 12.5, 6.25, 30.0, model.float_depth_m(p), current)
            veh.walls = False
            c, s = math.cos(veh.psi), math.sin(veh.psi)
            veh.u = current[0] * c + current[1] * s
            veh.v = -current[0] * s + current[1] * c
            x0, y0, seconds = veh.x, veh.y, 20.0
            for _ in range(int(seconds / model.DT_S)):
                veh.r = rate
                veh.step()
            drift = ((veh.x - x0) / seconds, (veh.y - y0) / seconds)
            for got, want in zip(drift, current):
                self.assertAlmostEqual(got, want, delta=0.002, msg=f"yaw rate {rate}: {drift}")

    def test_bad_arguments_name_the_argument(self):
        for args, word in ((["--hidden", "bogus"], "--hidden"),
                           (["--hidden", "water_current", "--size", "0.1"], "--size"),
                           (["--duration", "1"], "--duration")):
            p = subprocess.run([sys.executable, PROGRAM, "--program", "spins", "--out",
                                os.devnull + "-x", *args], capture_output=True, text=True)
            self.assertNotEqual(p.returncode, 0)
            self.assertIn(word, p.stderr)


class Calibration(unittest.TestCase):
    def test_open_loop_behaviour_matches_the_thesis(self):
        text = "\n".join(model.manoeuvres(model.Effects("none", None)))
        self.assertIn("top speed 0.44", text)
        turn = [line for line in text.splitlines() if line.startswith("spot turn clockwise (")][0]
        seconds = float(turn.split("one turn ")[1].split(" s")[0])
        self.assertTrue(21.0 <= seconds <= 26.0, turn)


if __name__ == "__main__":
    unittest.main()
