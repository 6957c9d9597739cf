/* The parts of a program built from several files (multi_main.c, multi_drive.c). */
#ifndef MULTI_H
#define MULTI_H
#include "include/eyebot.h"

extern MotorHandle ml, mr;
int drive_init(void);
void drive_for(int speed, int ticks);
#endif
