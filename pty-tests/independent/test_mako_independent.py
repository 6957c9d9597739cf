"""Checks of the independent model: run with `python3 -m unittest` in this directory."""

import csv
import filecmp
import json
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
