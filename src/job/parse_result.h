/* What reading a description (a command line, a scene) came to: a small
 * header of its own, so that the scene builder's callers (the library)
 * do not see the command line's options. */
#ifndef EF_PARSE_RESULT_H
#define EF_PARSE_RESULT_H

typedef enum ef_parse_result {
    EF_PARSE_RUN = 0, EF_PARSE_EXIT = 1, EF_PARSE_USAGE = -1, EF_PARSE_FAIL = -2
} ef_parse_result;

#endif
