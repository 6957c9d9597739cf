/*
 * eb_image.c - RoBIOS's basic image processing calls (IPLaplace, IPSobel, IPDither,
 * IPDiffer, IPColor2Grey) on its 82 x 62 images (80 x 60 with a border of one pixel).
 *
 * The RoBIOS reference names each operator and its arguments, not its scaling; the formulas
 * here are stated with each call. The operators that need neighbours write 0 on the border.
 */
#include <stdlib.h>

#include "eyebot.h"

static BYTE clamp255(int v) { return (BYTE)(v > 255 ? 255 : (v < 0 ? 0 : v)); }

static void clear_border(image *dest) {
    int r, c;
    for (c = 0; c < imagecolumns; c++) (*dest)[0][c] = (*dest)[imagerows - 1][c] = 0;
    for (r = 0; r < imagerows; r++) (*dest)[r][0] = (*dest)[r][imagecolumns - 1] = 0;
}

/* |4 centre - the four neighbours|, at most 255. */
int IPLaplace(image *src, image *dest) {
    int r, c;
    if (src == NULL || dest == NULL || src == dest) return -1;
    for (r = 1; r < imagerows - 1; r++)
        for (c = 1; c < imagecolumns - 1; c++)
            (*dest)[r][c] = clamp255(abs(4 * (*src)[r][c] - (*src)[r - 1][c] - (*src)[r + 1][c] -
                                         (*src)[r][c - 1] - (*src)[r][c + 1]));
    clear_border(dest);
    return 0;
}

/* (|Gx| + |Gy|) / 4 with the 3 x 3 Sobel kernels, at most 255. */
int IPSobel(image *src, image *dest) {
    int r, c;
    if (src == NULL || dest == NULL || src == dest) return -1;
    for (r = 1; r < imagerows - 1; r++)
        for (c = 1; c < imagecolumns - 1; c++) {
            int gx = (*src)[r - 1][c + 1] + 2 * (*src)[r][c + 1] + (*src)[r + 1][c + 1] -
                     (*src)[r - 1][c - 1] - 2 * (*src)[r][c - 1] - (*src)[r + 1][c - 1];
            int gy = (*src)[r + 1][c - 1] + 2 * (*src)[r + 1][c] + (*src)[r + 1][c + 1] -
                     (*src)[r - 1][c - 1] - 2 * (*src)[r - 1][c] - (*src)[r - 1][c + 1];
            (*dest)[r][c] = clamp255((abs(gx) + abs(gy)) / 4);
        }
    clear_border(dest);
    return 0;
}

/* 255 where the pixel exceeds the 2 x 2 pattern's threshold (0, 128 / 192, 64), else 0. */
int IPDither(image *src, image *dest) {
    static const int threshold[2][2] = {{0, 128}, {192, 64}};
    int r, c;
    if (src == NULL || dest == NULL) return -1;
    for (r = 0; r < imagerows; r++)
        for (c = 0; c < imagecolumns; c++)
            (*dest)[r][c] = (*src)[r][c] > threshold[r % 2][c % 2] ? 255 : 0;
    return 0;
}

/* |current - last| per pixel. */
int IPDiffer(image *current, image *last, image *dest) {
    int r, c;
    if (current == NULL || last == NULL || dest == NULL) return -1;
    for (r = 0; r < imagerows; r++)
        for (c = 0; c < imagecolumns; c++)
            (*dest)[r][c] = (BYTE)abs((*current)[r][c] - (*last)[r][c]);
    return 0;
}

/* (red + green + blue) / 3 per pixel. */
int IPColor2Grey(colimage *src, image *dest) {
    int r, c;
    if (src == NULL || dest == NULL) return -1;
    for (r = 0; r < imagerows; r++)
        for (c = 0; c < imagecolumns; c++)
            (*dest)[r][c] =
                (BYTE)(((*src)[r][c][0] + (*src)[r][c][1] + (*src)[r][c][2]) / 3);
    return 0;
}
