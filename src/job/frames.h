/* Frame sequences as oiiotool names them: a path holding a frame pattern
 * ('#' four digits, '@' one digit each, %0Nd or %d), a --frames list, and
 * the frames on disk that match a pattern. */
#ifndef EF_FRAMES_H
#define EF_FRAMES_H

#include <stddef.h>

#include "error.h"

/* The frame pattern found in a path: the text before and after it and the
 * number's width (0: as many digits as it takes). */
typedef struct ef_frame_pattern {
    int has;                  /* 0: the path holds no pattern */
    size_t at, len;           /* where the pattern is in the path, and its length */
    int width;
} ef_frame_pattern;

/* Finds the frame pattern of path: the last run of '#' (4 digits each), of
 * '@' (1 digit each), or a %0Nd / %d. Returns p->has. */
int ef_frame_pattern_find(const char *path, ef_frame_pattern *p);

/* Writes path with its pattern replaced by frame (zero-padded to the
 * width; negative frames as -0042). Returns 0, or -1 when out does not
 * hold it. */
int ef_frame_path(const char *path, const ef_frame_pattern *p, long frame, char *out, size_t len);

/* A --frames list: "1-100", "1-100x2", "1,5,10-20", "-5--1", in the order
 * given. Returns 0 with *frames (malloc'd) and *n, or -1 with a message. */
int ef_frames_parse(const char *text, long **frames, int *n, ef_err *err);

/* The frames on disk matching path's pattern, in increasing order: names
 * whose pattern part is an optional '-' and digits (exactly the width when
 * padded, or more digits when the frame needs them). Returns 0 with
 * *frames (malloc'd, possibly NULL when *n is 0), or -1 with a message
 * (the directory cannot be read). */
int ef_frames_on_disk(const char *path, const ef_frame_pattern *p, long **frames, int *n,
                      ef_err *err);

#endif
