/* Assertions shared by the cmocka test programs (include after cmocka.h). */
#ifndef EF_TASSERT_H
#define EF_TASSERT_H

#include <math.h>
#include <string.h>

/* |a - b| <= tol, printing both values on failure. */
#define assert_close(a, b, tol)                                                     \
    do {                                                                            \
        const double a_ = (a), b_ = (b);                                            \
        if (!(fabs(a_ - b_) <= (tol))) {                                            \
            print_error("%s = %.17g, expected %.17g (tol %g)\n", #a, a_, b_,        \
                        (double) (tol));                                            \
            fail();                                                                 \
        }                                                                           \
    } while (0)

/* needle occurs in hay. */
#define assert_contains(hay, needle)                                                \
    do {                                                                            \
        if (!strstr((hay), (needle))) {                                             \
            print_error("'%s' not found in:\n%s\n", (needle), (hay));              \
            fail();                                                                 \
        }                                                                           \
    } while (0)

#endif
