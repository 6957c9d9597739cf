#!/bin/sh
# The EyeBot program of the worked example (docs/gap.md): 20 s straight at 50 %, then 20 s
# turning, reading the compass and the depth channel every 0.2 s of simulated time.
P="eyebot-hil probe --link run/sensor"
$P thrusters 50 50 0 0
for i in $(seq 100); do $P advance 20 >/dev/null; $P compass >/dev/null; $P adc 0 >/dev/null; done
$P thrusters 60 -60 0 0
for i in $(seq 100); do $P advance 20 >/dev/null; $P compass >/dev/null; $P adc 0 >/dev/null; done
$P thrusters 0 0 0 0
