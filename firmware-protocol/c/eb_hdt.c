/*
 * eb_hdt.c - Mako's hardware description table: the motor balancing table (thesis 4.3) for
 * MOTORDrive, and the device list that maps RoBIOS device semantics onto Mako's devices.
 *
 * The balancing table is GENERATED from configs/vehicles/mako.toml ([[thruster]] hdt_duty, in
 * tenths of a duty step); do not edit it by hand. To regenerate after changing the TOML:
 *
 *     EYEBOT_HDT_REGENERATE=1 cargo test -p pty-tests --test eyebot_c_hdt
 *
 * Without the variable that test fails when the table and the TOML disagree. The device list
 * (eb_hdt_devices, below the table) is edited here, as a RoBIOS HDT is.
 */
#include "eb_hdt.h"

#include <stddef.h>

#include "eyebot.h"

/* Rows: port, starboard, bow, stern. Columns: 0, 10, ..., 100 % (duty x 10). */
static const uint16_t hdt_duty_x10[4][11] = {
    {2550, 2066, 1836, 1607, 1377, 1148, 918, 689, 459, 230, 0}, /* port */
    {2550, 2066, 1836, 1607, 1377, 1148, 918, 689, 459, 230, 0}, /* starboard */
    {2550, 2066, 1836, 1607, 1377, 1148, 918, 689, 459, 230, 0}, /* bow */
    {2550, 2066, 1836, 1607, 1377, 1148, 918, 689, 459, 230, 0}, /* stern */
};

uint8_t eb_hdt_duty(int thruster, int percent) {
    const uint16_t *row;
    long lo, hi, frac, x10;
    if (thruster < 0 || thruster > 3) return 0xFF;
    if (percent <= 0) return 0xFF;
    if (percent > 100) percent = 100;
    row = hdt_duty_x10[thruster];
    lo = row[percent / 10];
    hi = row[percent / 10 < 10 ? percent / 10 + 1 : 10];
    frac = percent % 10;
    /* duty x 100, then round half up to an integer duty */
    x10 = lo * 10 + (hi - lo) * frac;
    return (uint8_t)((x10 + 50) / 100);
}

/* The device list: which Mako device each semantics names. Thrusters 0..3 are port,
 * starboard, bow, stern (PROTOCOL.md 2.7); sonar transducers 1..4 are the multiplexer's
 * numbers (PROTOCOL.md 1.2; configs/sensors/mako-2008.toml mounts them: 1 port-fore, 75 deg
 * to port; 2 port-aft, 105 deg to port; 3 bow-port, 15 deg to port; 4 bow-starboard, 15 deg
 * to starboard). Mako has no transducer facing aft or to starboard: PSD_BACK and PSD_RIGHT
 * name the two that are left, so that a program written for SubSim's four PSDs reads four
 * transducers. Several names may share a device. */
static const struct {
    int kind;
    int semantics;
    int device;
    const char *name;
} eb_hdt_devices[] = {
    {EB_HDT_MOTOR, MOTOR_PORT, 0, "MOTOR_PORT"},
    {EB_HDT_MOTOR, MOTOR_STARBOARD, 1, "MOTOR_STARBOARD"},
    {EB_HDT_MOTOR, MOTOR_BOW, 2, "MOTOR_BOW"},
    {EB_HDT_MOTOR, MOTOR_STERN, 3, "MOTOR_STERN"},
    {EB_HDT_MOTOR, MOTOR_LEFT, 0, "MOTOR_LEFT"},
    {EB_HDT_MOTOR, MOTOR_RIGHT, 1, "MOTOR_RIGHT"},
    {EB_HDT_MOTOR, MOTOR_FRONT, 2, "MOTOR_FRONT"},
    {EB_HDT_MOTOR, MOTOR_BACK, 3, "MOTOR_BACK"},
#ifndef EYEBOT_BACKEND_ROBIOS
    {EB_HDT_PSD, PSD_LEFT, 1, "PSD_LEFT"},
    {EB_HDT_PSD, PSD_BACK, 2, "PSD_BACK"},
    {EB_HDT_PSD, PSD_FRONT, 3, "PSD_FRONT"},
    {EB_HDT_PSD, PSD_RIGHT, 4, "PSD_RIGHT"},
    {EB_HDT_PSD, PSD_FRONTLEFT, 3, "PSD_FRONTLEFT"},
    {EB_HDT_PSD, PSD_FRONTRIGHT, 4, "PSD_FRONTRIGHT"},
    {EB_HDT_PSD, PSD_BACKLEFT, 2, "PSD_BACKLEFT"},
#endif
};

#define DEVICES (sizeof eb_hdt_devices / sizeof eb_hdt_devices[0])

int eb_hdt_device(int kind, int semantics) {
    size_t i;
    for (i = 0; i < DEVICES; i++)
        if (eb_hdt_devices[i].kind == kind && eb_hdt_devices[i].semantics == semantics)
            return eb_hdt_devices[i].device;
    return -1;
}

const char *eb_hdt_name(int kind, size_t index) {
    size_t i, n = 0;
    for (i = 0; i < DEVICES; i++)
        if (eb_hdt_devices[i].kind == kind && n++ == index) return eb_hdt_devices[i].name;
    return NULL;
}
