/* The ESC's memory access helpers, its AL event request and the SYNC0 registers, shared
 * by the compiled paths (ecatsim/esc/_sm.h and through it _logical.c and _cycle.c;
 * _dcloop.c). Each function transcribes the Python method it names;
 * ecatsim/esc/core.py Esc is the reference.
 * Ref: TMC8460 §5.32 (AL event request), §5.33 (AL event mask).
 */
#ifndef ECATSIM_EVENTS_H
#define ECATSIM_EVENTS_H
#include <Python.h>
#include <stdint.h>

/* Register addresses (ecatsim/esc/regs.py; the tests check they agree). */
#define AL_EVENT_MASK 0x0204
#define AL_EVENT_REQUEST 0x0220
#define DC_ACTIVATION 0x0981
#define DC_ACTIVATION_STATUS 0x0984
#define DC_SYNC0_STATUS 0x098E
#define EV_SYNC0 0x0004

static inline uint32_t rd32(const uint8_t *m, int a)
{
    return (uint32_t)m[a] | ((uint32_t)m[a + 1] << 8) | ((uint32_t)m[a + 2] << 16) |
           ((uint32_t)m[a + 3] << 24);
}

static inline void wr32(uint8_t *m, int a, uint32_t v)
{
    m[a] = (uint8_t)v;
    m[a + 1] = (uint8_t)(v >> 8);
    m[a + 2] = (uint8_t)(v >> 16);
    m[a + 3] = (uint8_t)(v >> 24);
}

static inline unsigned rd16(const uint8_t *m, int a) { return m[a] | (m[a + 1] << 8); }

static inline void wr16(uint8_t *m, int a, unsigned v)
{
    m[a] = (uint8_t)v;
    m[a + 1] = (uint8_t)(v >> 8);
}

/* The ESC side of one call: memory, and what the event functions touch. */
typedef struct {
    uint8_t *m;
    PyObject *esc, *ctx, *pending, *position;
} Esc;

/* Esc._pdi_irq: the PDI interrupt line is AL event request AND AL event mask. */
static inline int pdi_irq(Esc *e, uint32_t request)
{
    if (request & rd32(e->m, AL_EVENT_MASK))
        return PySet_Add(e->pending, e->position);
    return PySet_Discard(e->pending, e->position) < 0 ? -1 : 0;
}

/* Esc.set_al_event / clr_al_event */
static inline int set_al_event(Esc *e, uint32_t bits)
{
    uint32_t v = rd32(e->m, AL_EVENT_REQUEST) | bits;
    wr32(e->m, AL_EVENT_REQUEST, v);
    return pdi_irq(e, v);
}

static inline int clr_al_event(Esc *e, uint32_t bits)
{
    uint32_t v = rd32(e->m, AL_EVENT_REQUEST);
    if (!(v & bits))
        return 0;
    v &= ~bits;
    wr32(e->m, AL_EVENT_REQUEST, v);
    return pdi_irq(e, v);
}

#endif
