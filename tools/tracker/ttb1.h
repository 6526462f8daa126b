/*
 * ttb1.h: the tracker's ball observation for topspin (DESIGN §5.1), one
 * header, C99, no dependencies beyond the C library.
 *
 * One UDP datagram per triangulated ball, 36 bytes, little-endian:
 *
 *   offset type     field
 *   0      u8[4]    magic "TTB1"
 *   4      u32      sequence number (wrapping)
 *   8      u64      capture time, ns, the tracker's monotonic clock
 *   16     f32 x3   x, y, z in m, table frame
 *   28     f32      triangulation residual in m (NaN if unknown)
 *   32     u16      number of cameras that saw the ball
 *   34     u16      flags (bit 0: valid ball; other bits 0)
 *
 * ttb1_encode() writes the bytes explicitly little-endian, so it is right on
 * any host byte order; send them with sendto(2) to topspin's tracker port.
 */
#ifndef TOPSPIN_TTB1_H
#define TOPSPIN_TTB1_H

#include <stdint.h>
#include <string.h>

#define TTB1_LEN 36
#define TTB1_FLAG_VALID 0x0001u

typedef struct {
    uint32_t seq;        /* wrapping sequence number */
    uint64_t capture_ns; /* the tracker's monotonic clock */
    float x, y, z;       /* m, table frame */
    float residual;      /* m; NAN if unknown */
    uint16_t cameras;    /* cameras that saw the ball */
    uint16_t flags;      /* TTB1_FLAG_VALID for a ball */
} ttb1_observation;

static inline void ttb1_put_u16(uint8_t *p, uint16_t v) {
    p[0] = (uint8_t)v;
    p[1] = (uint8_t)(v >> 8);
}

static inline void ttb1_put_u32(uint8_t *p, uint32_t v) {
    for (int i = 0; i < 4; i++) p[i] = (uint8_t)(v >> (8 * i));
}

static inline void ttb1_put_u64(uint8_t *p, uint64_t v) {
    for (int i = 0; i < 8; i++) p[i] = (uint8_t)(v >> (8 * i));
}

static inline void ttb1_put_f32(uint8_t *p, float f) {
    uint32_t bits;
    memcpy(&bits, &f, sizeof bits);
    ttb1_put_u32(p, bits);
}

/* Writes the 36 bytes of `o` into `out`. */
static inline void ttb1_encode(const ttb1_observation *o, uint8_t out[TTB1_LEN]) {
    memcpy(out, "TTB1", 4);
    ttb1_put_u32(out + 4, o->seq);
    ttb1_put_u64(out + 8, o->capture_ns);
    ttb1_put_f32(out + 16, o->x);
    ttb1_put_f32(out + 20, o->y);
    ttb1_put_f32(out + 24, o->z);
    ttb1_put_f32(out + 28, o->residual);
    ttb1_put_u16(out + 32, o->cameras);
    ttb1_put_u16(out + 34, o->flags);
}

#endif /* TOPSPIN_TTB1_H */
