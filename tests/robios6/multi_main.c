/* The main file of a program built from two files, as some RoBIOS demos are. */
#include "multi.h"

int main(void)
{
  if (drive_init() != 0)
  {
    LCDPutString("no drive\n");
    return 1;
  }
  drive_for(30, 200);
  drive_for(0, 10);
  LCDPrintf("done at %d\n", OSGetCount());
  return 0;
}
