/*
 * eb_hdt.c - Mako's HDT motor balancing table (thesis 4.3), for MOTORDrive.
 *
 * GENERATED from configs/vehicles/mako.toml ([[thruster]] hdt_duty, in tenths of a duty
 * step). Do not edit by hand. To regenerate after changing the TOML:
 *
 *     EYEBOT_HDT_REGENERATE=1 cargo test -p pty-tests --test eyebot_c_hdt
 *
 * Without the variable that test fails when this file and the TOML disagree.
 */
#include "eb_hdt.h"

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
