/* A demo menu's worth of RoBIOS 6.3 calls, the way the EyeBot M5's standard demos use them:
 * a tune kept as an array of notes and played one by one, the microphone's level, the camera
 * started wide and then normal (retried after an init error, given up without a camera, a
 * colour camera told from a greyscale one), the slowest frame rates, and the v-omega driver.
 * It prints what it found; a robot without a device says so and goes on. */
#include "include/eyebot.h"

#define VERSION "6.3"

/* C major arpeggio, then the end mark. */
tone fanfare[] = { {523, 120}, {659, 120}, {784, 120}, {1047, 240}, {0, 0} };

int play(tone *tune)
{ int n;

  for (n = 0; tune[n].freq != 0 && tune[n].len != 0; n++)
  { AUTone(tune[n].freq, tune[n].len);
    while (!AUCheckTone());  /* let the note sound out */
  }
  return n;
}

/* CAMInit, tried again up to `retries` times while the camera reports an init error. */
int camstart(int mode, int retries)
{ int version = CAMInit(mode);

  while (version != NOCAM && version >= INITERROR && retries-- > 0)
  { LCDPrintf("I%d ", version);
    OSWait(CAMWAIT);
    version = CAMInit(mode);
  }
  return version;
}

const char *camkind(int version)
{ if (version == NOCAM) return "No Camera";
  if (version >= INITERROR) return "init error";
  if (version < COLCAM) return "greyscale";
  return "colour";
}

int main(void)
{ int version, fps, refused = 0;
  VWHandle vw;

  LCDPutString("Demos " VERSION "\n");
  LCDPrintf("fanfare: %d notes\n", play(fanfare));
  LCDPrintf("Micro: %d\n", AUCaptureMic());

  version = camstart(WIDE, 3);
  LCDPrintf("wide: %s\n", camkind(version));
  if (version != NOCAM && version < INITERROR) CAMRelease();

  version = camstart(NORMAL, 3);
  LCDPrintf("CAMSet slow %d\n", CAMSet(FPS0_9375, 0, 0));
  LCDPrintf("normal: %s\n", camkind(version));
  for (fps = FPS1_875; fps <= FPS0_46875; fps++)  /* down to the slowest rate */
    if (CAMSet(fps, 0, 0) != 0) refused++;
  LCDPrintf("rates refused %d\n", refused);
  CAMRelease();

  vw = VWInit(VW, 1);
  if (vw == 0) LCDPutString("no VW driver\n");
  else
  { VWStartControl(vw, 7, 0.3, 7, 0.1);
    VWDriveStraight(vw, 0.2, 0.1);
    while (!VWDriveDone(vw)) OSWait(10);
    VWRelease(vw);
  }
  LCDPutString("done\n");
  return 0;
}
