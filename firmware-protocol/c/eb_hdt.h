/*
 * eb_hdt.h - the HDT motor balancing table (thesis 4.3): MOTORDrive percent -> PWM duty.
 *
 * Internal to libeyebot. The values live in eb_hdt.c, generated from the `hdt_duty` arrays
 * of configs/vehicles/mako.toml (see the comment there for how to regenerate them).
 */
#ifndef EYEBOT_HIL_EB_HDT_H
#define EYEBOT_HIL_EB_HDT_H

#include <stdint.h>

/* PWM duty byte (Mako's inverted logic: 0 = full thrust, 255 = off) for thruster 0..3
 * (port, starboard, bow, stern) at `percent` 0..100, interpolated linearly between the
 * table's 10 % steps and rounded to the nearest integer. */
uint8_t eb_hdt_duty(int thruster, int percent);

#endif
