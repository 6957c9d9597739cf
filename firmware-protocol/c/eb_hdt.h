/*
 * eb_hdt.h - the HDT: the motor balancing table (thesis 4.3: MOTORDrive percent -> PWM duty)
 * and the device list (device semantics -> Mako device).
 *
 * Internal to libeyebot. The values live in eb_hdt.c; the balancing table is generated from
 * the `hdt_duty` arrays of configs/vehicles/mako.toml (see the comment there).
 */
#ifndef EYEBOT_HIL_EB_HDT_H
#define EYEBOT_HIL_EB_HDT_H

#include <stddef.h>
#include <stdint.h>

/* PWM duty byte (Mako's inverted logic: 0 = full thrust, 255 = off) for thruster 0..3
 * (port, starboard, bow, stern) at `percent` 0..100, interpolated linearly between the
 * table's 10 % steps and rounded to the nearest integer. */
uint8_t eb_hdt_duty(int thruster, int percent);

/* Kinds of device in the device list. */
#define EB_HDT_MOTOR 1
#define EB_HDT_PSD 2

/* The device the HDT names `semantics` among devices of `kind`: thruster 0..3 for
 * EB_HDT_MOTOR, sonar transducer 1..4 for EB_HDT_PSD; -1 when the HDT has no such name. */
int eb_hdt_device(int kind, int semantics);
/* The index-th name of a `kind` in the device list, NULL past the last (for messages). */
const char *eb_hdt_name(int kind, size_t index);

#endif
