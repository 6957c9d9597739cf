/* RoBIOS's basic image processing on a picture with a vertical edge (dark left half,
 * bright right half) and a colour picture: prints what each operator gives. */
#include <stdio.h>
#include "eyebot.h"

image a, b, out;
colimage col;

int main(void)
{
  int r, c, edge = 0, flat = 0;
  for (r = 0; r < imagerows; r++)
    for (c = 0; c < imagecolumns; c++)
    {
      a[r][c] = c < 41 ? 20 : 220;
      b[r][c] = 20;
      col[r][c][0] = 30; col[r][c][1] = 60; col[r][c][2] = 90;
    }
  IPLaplace(&a, &out);
  for (r = 1; r < imagerows - 1; r++)
    for (c = 1; c < imagecolumns - 1; c++)
      if (out[r][c] != 0) edge += c == 40 || c == 41; else flat++;
  printf("laplace %d %d at edge %d %d border %d\n", out[30][40], out[30][41], edge, flat, out[0][40]);
  IPSobel(&a, &out);
  printf("sobel %d %d %d %d\n", out[30][39], out[30][40], out[30][41], out[30][42]);
  IPDither(&a, &out);
  printf("dither %d %d %d %d\n", out[10][10], out[10][11], out[10][60], out[11][60]);
  IPDiffer(&a, &b, &out);
  printf("differ %d %d\n", out[5][5], out[5][70]);
  IPColor2Grey(&col, &out);
  printf("grey %d\n", out[7][7]);
  printf("null %d\n", IPLaplace(0, &out));
  return 0;
}
