/* Threads in the style of the RoBIOS 6 multitasking examples: the thread function is
 * handed to OSSpawn cast to int, as programs written for the 68332 (where a pointer fits in
 * an int) do. Builds with gcc's pointer/int warnings; runs on the host and the 68k alike. */
#include <stdio.h>
#include "eyebot.h"

struct sem done;
int count;

void worker(void)
{
    int i;
    for (i = 0; i < 3; i++) {
        count++;
        OSReschedule();
    }
    OSSemV(&done);
    OSKill(0);
}

int main(void)
{
    struct tcb *t;
    OSMTInit(COOP);
    OSSemInit(&done, 0);
    t = OSSpawn("worker", (int)worker, 4096, MIN_PRI, 1);
    if (t == NULL) {
        printf("spawn failed\n");
        return 1;
    }
    OSReady(t);
    OSSemP(&done);
    printf("worker ran %d times\n", count);
    return 0;
}
