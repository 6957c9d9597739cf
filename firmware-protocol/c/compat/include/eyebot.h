/* The RoBIOS distribution's programs include "include/eyebot.h": this is libeyebot's. */
#include "../../eyebot.h"
