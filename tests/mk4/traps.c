/* Silent traps that must not be silent. argv[1]: "key" waits for KEY4 ("press GO"),
 * "motor" drives a motor that was never initialised. */
#include <string.h>

#include "eyebot.h"

int main(int argc, char **argv) {
    if (argc > 1 && strcmp(argv[1], "key") == 0) {
        LCDPrintf("press GO\n");
        KEYWait(KEY4);
        LCDPrintf("going\n");
        return 0;
    }
    if (argc > 1 && strcmp(argv[1], "motor") == 0) {
        MOTORDrive(1, 50);
        OSWait(100);
        LCDPrintf("drove\n");
        return 0;
    }
    return 2;
}
