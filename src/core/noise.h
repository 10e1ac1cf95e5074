/* Ken Perlin's Improved Noise (SIGGRAPH 2002, with his 2003 gradient fix)
 * and the fractal sum exrfog builds its heterogeneous fog from. Both are a
 * public contract: an implementation in any language that follows the
 * reference (his permutation, fade 6t^5-15t^4+10t^3, gradients, lerp
 * a + t(b - a) in his nesting order, binary64 without fused multiply-adds)
 * reproduces these values bit for bit. noise.c is built with
 * -ffp-contract=off for that reason. */
#ifndef EF_NOISE_H
#define EF_NOISE_H

#include <stdint.h>

/* Perlin's noise at (x, y, z): 0 at every lattice point, period 256 in each
 * axis, |noise| <= EF_NOISE_BOUND. The cell index is floor(x) & 255, taken
 * exactly for every finite x (Java's int cast would saturate past 2^31). */
double ef_noise3(double x, double y, double z);

/* The eight corner hashes of one lattice cell (indices & 255). */
typedef struct ef_noise_cell {
    unsigned char h[8];    /* AA, BA, AB, BB, AA+1, BA+1, AB+1, BB+1 */
} ef_noise_cell;

/* Perlin's permutation as a list, X(v) per entry in order: one source for
 * ef_noise_perm and the integrators' derived tables. */
#define EF_NOISE_PERM(X) \
    X(151) X(160) X(137) X(91) X(90) X(15) X(131) X(13) X(201) X(95) X(96) X(53) X(194) X(233) \
    X(7) X(225) X(140) X(36) X(103) X(30) X(69) X(142) X(8) X(99) X(37) X(240) X(21) X(10) \
    X(23) X(190) X(6) X(148) X(247) X(120) X(234) X(75) X(0) X(26) X(197) X(62) X(94) X(252) \
    X(219) X(203) X(117) X(35) X(11) X(32) X(57) X(177) X(33) X(88) X(237) X(149) X(56) X(87) \
    X(174) X(20) X(125) X(136) X(171) X(168) X(68) X(175) X(74) X(165) X(71) X(134) X(139) \
    X(48) X(27) X(166) X(77) X(146) X(158) X(231) X(83) X(111) X(229) X(122) X(60) X(211) \
    X(133) X(230) X(220) X(105) X(92) X(41) X(55) X(46) X(245) X(40) X(244) X(102) X(143) \
    X(54) X(65) X(25) X(63) X(161) X(1) X(216) X(80) X(73) X(209) X(76) X(132) X(187) X(208) \
    X(89) X(18) X(169) X(200) X(196) X(135) X(130) X(116) X(188) X(159) X(86) X(164) X(100) \
    X(109) X(198) X(173) X(186) X(3) X(64) X(52) X(217) X(226) X(250) X(124) X(123) X(5) \
    X(202) X(38) X(147) X(118) X(126) X(255) X(82) X(85) X(212) X(207) X(206) X(59) X(227) \
    X(47) X(16) X(58) X(17) X(182) X(189) X(28) X(42) X(223) X(183) X(170) X(213) X(119) \
    X(248) X(152) X(2) X(44) X(154) X(163) X(70) X(221) X(153) X(101) X(155) X(167) X(43) \
    X(172) X(9) X(129) X(22) X(39) X(253) X(19) X(98) X(108) X(110) X(79) X(113) X(224) X(232) \
    X(178) X(185) X(112) X(104) X(218) X(246) X(97) X(228) X(251) X(34) X(242) X(193) X(238) \
    X(210) X(144) X(12) X(191) X(179) X(162) X(241) X(81) X(51) X(145) X(235) X(249) X(14) \
    X(239) X(107) X(49) X(192) X(214) X(31) X(181) X(199) X(106) X(157) X(184) X(84) X(204) \
    X(176) X(115) X(121) X(50) X(45) X(127) X(4) X(150) X(254) X(138) X(236) X(205) X(93) \
    X(222) X(114) X(67) X(29) X(24) X(72) X(243) X(141) X(128) X(195) X(78) X(66) X(215) X(61) \
    X(156) X(180)

/* Perlin's permutation (his reference replicates it to 512 entries so that
 * p[A + 1] needs no mask; indexing with & 255 reads the same values). */
extern const unsigned char ef_noise_perm[256];

/* The corners of the cell whose lower corner is (X, Y, Z) & 255. Inline:
 * the integrators hash every lattice cell they walk. */
static inline void ef_noise_cell_at(int64_t X, int64_t Y, int64_t Z, ef_noise_cell *c)
{
    const unsigned char *p = ef_noise_perm;
    const int x = (int) (X & 255), y = (int) (Y & 255), z = (int) (Z & 255);
    const int A = p[x] + y, AA = p[A & 255] + z, AB = p[(A + 1) & 255] + z;
    const int B = p[(x + 1) & 255] + y, BA = p[B & 255] + z, BB = p[(B + 1) & 255] + z;
    c->h[0] = p[AA & 255];
    c->h[1] = p[BA & 255];
    c->h[2] = p[AB & 255];
    c->h[3] = p[BB & 255];
    c->h[4] = p[(AA + 1) & 255];
    c->h[5] = p[(BA + 1) & 255];
    c->h[6] = p[(AB + 1) & 255];
    c->h[7] = p[(BB + 1) & 255];
}

/* Noise inside cell c at fractions (x, y, z) in [0, 1]: the same operations
 * as ef_noise3 after its floor, so ef_noise3 equals it bit for bit (in files
 * built with -ffp-contract=off). Inside a cell the noise is a polynomial
 * (degree 16 along any line). Inline: the integrators call it per node. */
static inline double ef_noise_fade_(double t)
{
    return t * t * t * (t * (t * 6 - 15) + 10);
}

static inline double ef_noise_lerp_(double t, double a, double b)
{
    return a + t * (b - a);
}

static inline double ef_noise_grad_(int hash, double x, double y, double z)
{
    const int h = hash & 15;
    const double u = h < 8 ? x : y;
    const double v = h < 4 ? y : (h == 12 || h == 14 ? x : z);
    return ((h & 1) == 0 ? u : -u) + ((h & 2) == 0 ? v : -v);
}

static inline double ef_noise_cell_eval(const ef_noise_cell *c, double x, double y, double z)
{
    const double u = ef_noise_fade_(x), v = ef_noise_fade_(y), w = ef_noise_fade_(z);
    const unsigned char *h = c->h;
    return ef_noise_lerp_(
        w,
        ef_noise_lerp_(v,
                       ef_noise_lerp_(u, ef_noise_grad_(h[0], x, y, z),
                                      ef_noise_grad_(h[1], x - 1, y, z)),
                       ef_noise_lerp_(u, ef_noise_grad_(h[2], x, y - 1, z),
                                      ef_noise_grad_(h[3], x - 1, y - 1, z))),
        ef_noise_lerp_(v,
                       ef_noise_lerp_(u, ef_noise_grad_(h[4], x, y, z - 1),
                                      ef_noise_grad_(h[5], x - 1, y, z - 1)),
                       ef_noise_lerp_(u, ef_noise_grad_(h[6], x, y - 1, z - 1),
                                      ef_noise_grad_(h[7], x - 1, y - 1, z - 1))));
}

/* The cell index (floor(v) & 255) and fraction v - floor(v), as ef_noise3
 * takes them. */
void ef_noise_split(double v, int64_t *cell, double *frac);

/* max |noise| over all gradient assignments (Perlin's 12 directions), the
 * bound every rigorous estimate here uses; its Lipschitz constant per
 * lattice unit; and max |d2 noise/ds2| along a unit direction. */
#define EF_NOISE_BOUND 1.0363538
#define EF_NOISE_LIPSCHITZ 3.75
#define EF_NOISE_CURVATURE 14.5

#define EF_FBM_MAX_OCTAVES 16

/* The fractal sum fbm(q) = sum_i g^i noise3(l^i q + i O) / sum_i g^i,
 * O = (31.416, 27.183, 14.142). freq[i] = l^i and weight[i] = g^i / sum g^j
 * are formed by repeated multiplication (freq[0] = 1, freq[i+1] = freq[i] l),
 * then the sum of g^i n_i is divided by the sum of g^i, in order i = 0.. */
typedef struct ef_fbm {
    int octaves;                         /* 1..EF_FBM_MAX_OCTAVES */
    double lacunarity, gain;
    double freq[EF_FBM_MAX_OCTAVES];     /* l^i */
    double amp[EF_FBM_MAX_OCTAVES];      /* g^i */
    double norm;                         /* sum g^i */
    double weight[EF_FBM_MAX_OCTAVES];   /* g^i / norm, for the integrators */
} ef_fbm;

/* The per-octave offset O. */
extern const double ef_fbm_offset[3];
/* The seed direction S of q = (p - offset - velocity t) / scale + seed S. */
extern const double ef_noise_seed_dir[3];

/* Fills f for octaves in 1..16, lacunarity > 1, gain > 0. */
void ef_fbm_init(ef_fbm *f, int octaves, double lacunarity, double gain);

/* fbm(q) as defined above; |fbm| <= EF_NOISE_BOUND. */
double ef_fbm_eval(const ef_fbm *f, const double q[3]);

/* Octave i's noise coordinates of q: l^i q + i O (the contract's order). */
void ef_fbm_octave_point(const ef_fbm *f, int i, const double q[3], double u[3]);

#endif
