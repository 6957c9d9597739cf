/*
 * eb_port.h - what the portable core (eyebot.c) needs from a back-end.
 *
 * Internal to libeyebot. Two implementations: eb_posix.c (termios; hosts and qemu-m68k) and
 * eb_robios.c (a real EyeBot, on the RoBIOS serial calls). Exactly one is compiled in.
 *
 * Links: EB_LINK_SENSOR is the bridge's binary sensor link; 1..3 are the program's SERIAL1..3.
 */
#ifndef EYEBOT_HIL_EB_PORT_H
#define EYEBOT_HIL_EB_PORT_H

#include <stddef.h>
#include <stdint.h>

#define EB_LINK_SENSOR 0
#define EB_LINKS 4

/* Opens a link. baud_code is one of the SERxxxx constants of the program's eyebot.h, or -1
 * for the link's configured default. 0 on success, -1 on error (message already printed). */
int eb_port_open(int link, int baud_code);
/* Writes all n bytes; 0 on success, -1 on error. */
int eb_port_write(int link, const uint8_t *data, size_t n);
/* Reads up to cap bytes, waiting at most timeout_ms (0: do not wait). Returns the number of
 * bytes (> 0), 0 on timeout, -1 on error. */
long eb_port_read(int link, uint8_t *buf, size_t cap, long timeout_ms);
/* Drops bytes waiting in the driver. */
void eb_port_flush_in(int link);
/* POSIX back-end only (RoBIOS has its own OSFlushOutRS232/OSCheckOutRS232): drops the bytes
 * written and not yet sent; the number of such bytes. */
void eb_port_flush_out(int link);
long eb_port_out_pending(int link);
/* 1 when the link is open. */
int eb_port_is_open(int link);

/* Host clock in milliseconds (monotonic; any origin) and a real sleep. */
long eb_clock_ms(void);
void eb_sleep_ms(long ms);

/* A configuration value by name (EYEBOT_...), or NULL when unset. POSIX: the environment;
 * RoBIOS: compile-time macros. */
const char *eb_config(const char *name);

/* A diagnostic for the user (stderr on hosts, the LCD on an EyeBot). */
void eb_report(const char *message);
/* Ends the program with `status` after reporting `message`. */
void eb_exit(int status, const char *message);

#endif
