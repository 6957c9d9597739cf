/* A camera and radio demo in the style of the RoBIOS 6 ROM demos: grab a frame, show it,
 * send a message to the other robots, play a sample. */
#include "include/eyebot.h"

image img;
colimage cimg;
BYTE sample[64];

int main(void)
{
  int cam, rad, i, got = 0, size = 0;
  BYTE from, msg[MAXMSGLEN];
  IDList others;

  cam = CAMInit(NORMAL);
  if (cam == NOCAM || cam == INITERROR)
    LCDPutString("no camera\n");
  for (i = 0; i < 3; i++)
  {
    img[1][1] = 7;
    if (CAMGetFrame(&img) == 0) LCDPutGraphic(&img);
    else LCDPrintf("frame %d: error, pixel %d\n", i, img[1][1]);
  }
  LCDPrintf("colour %d mode %d\n", CAMGetColFrame(&cimg, 0), CAMMode(AUTOBRIGHTNESS));
  rad = RADIOInit();
  LCDPrintf("RADIOInit %d\n", rad);
  msg[0] = 'h';
  LCDPrintf("RADIOSend %d RADIOCheck %d\n", RADIOSend(BROADCAST, 1, msg), RADIOCheck());
  rad = RADIORecv(&from, &size, msg);
  LCDPrintf("RADIORecv %d size %d\n", rad, size);
  others.count = 5;
  rad = RADIOStatus(&others);
  LCDPrintf("RADIOStatus %d count %d\n", rad, others.count);
  LCDPrintf("AUPlaySample %d AUCheckSample %d\n", AUPlaySample(sample), AUCheckSample());
  LCDPrintf("AURecordSample %d\n", AURecordSample(sample, 64, 5000));
  LCDPrintf("IRTVInit %d IRTVPressed %d\n", IRTVInit(1, 13, 0, 0, 0, 4, 10), IRTVPressed());
  RADIOTerm();
  CAMRelease();
  got = 1;
  LCDPrintf("done %d\n", got);
  return 0;
}
