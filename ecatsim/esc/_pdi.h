/* The ESC's PDI face for compiled firmware (ecatsim/slave/_cycle.c): the accesses
 * ecatsim/esc/pdi.py gives the Python firmware, each naming the Python it transcribes.
 * Firmware code includes this header, never the ESC's internals (the seam the layering
 * test checks: tests/unit/test_layering.py). An SM's state is read with pdi_sm_load()
 * and written back by the calls that change it.
 * Ref: TMC8460 §5.19 (DL status), §5.32 (AL event), §5.49 Tables 88-91 (SM status and
 * PDI control, 3-buffer exchange), §5.50.4 Tables 106-109 (SYNC0 status).
 */
#ifndef ECATSIM_PDI_H
#define ECATSIM_PDI_H
#include "_sm.h"

#define SM_ACT_LATCH_PDI 0x80 /* ecatsim/esc/regs.py */

/* Pdi.operational: DL status 0x0110.0, EEPROM loaded and PDI operational. */
static inline int pdi_operational(const Esc *e) { return e->m[DL_STATUS] & 0x01; }

/* Pdi.al_event: AL event request 0x0220 (no read side effect). */
static inline uint32_t pdi_al_event(const Esc *e) { return rd32(e->m, AL_EVENT_REQUEST); }

/* Pdi.u8 of 0x0981 and 0x0984: SYNC0 generation on, and its first pulse done. */
static inline int pdi_sync0_running(const Esc *e)
{
    return (e->m[DC_ACTIVATION] & 0x03) == 0x03 && !(e->m[DC_ACTIVATION_STATUS] & 0x01);
}

/* Pdi.u8(DC_SYNC0_STATUS) for its side effect (Esc._pr_dc_sync_status): the SYNC0 AL
 * event is acknowledged, and with pulse length 0 (acknowledge mode) the status too. */
static inline int pdi_ack_sync0(Esc *e)
{
    if (clr_al_event(e, EV_SYNC0) < 0)
        return -1;
    if (!(e->m[DC_PULSE_LENGTH] | e->m[DC_PULSE_LENGTH + 1]))
        e->m[DC_SYNC0_STATUS] &= 0xFE;
    return 0;
}

/* The SM's state, read from the chip (SyncManager); -1 on failure. */
static inline int pdi_sm_load(Sm *sm, PyObject *obj) { return sm_load(sm, obj); }

/* Whole-buffer PDI access of a buffered SM is possible (SyncManager.pdi_may_read /
 * pdi_may_write) and asks for no PDI event times (0x0806+8n bit 7: Esc.pdi_buffer_event
 * stamps 0x09F8/0x09FC; the Python firmware serves such an SM). */
static inline int pdi_sm_may(const Esc *e, const Sm *sm, int reading)
{
    return !(e->m[sm->status_addr + 1] & SM_ACT_LATCH_PDI) && sm->active && !sm->locked &&
           !sm->mailbox && (reading ? sm->ecat_side_writes : !sm->ecat_side_writes) &&
           sm->length > 0 && sm->start + 3 * sm->length <= MEM_SIZE;
}

/* Pdi.sm_read: SyncManager.reader_read(0, whole) -> _reader_open, _reader_access(first,
 * last). The buffer (the caller copies it out now), or NULL with the exception set. */
static inline const uint8_t *pdi_sm_read(Esc *e, Sm *sm)
{
    if (sm->l >= 0)
        sm->r = sm->l;
    else if (sm->r == sm->w)
        sm->r = (sm->w + 1) % 3;
    long base = sm->start + sm->r * sm->length; /* read open only during the copy */
    sm->status &= ~SM_ST_IRQ_WRITE;
    sm->r_open = 0;
    sm->status |= SM_ST_IRQ_READ;
    if (sm_sync(e, sm) < 0 || sm_store(sm) < 0)
        return NULL;
    return e->m + base;
}

/* Pdi.sm_write, first half: the buffer the PDI writes (SyncManager.writer_write). */
static inline uint8_t *pdi_sm_write_buffer(Esc *e, const Sm *sm)
{
    return e->m + sm->start + sm->w * sm->length;
}

/* Pdi.sm_write, second half, once the buffer is filled: _writer_access(first, last). */
static inline int pdi_sm_written(Esc *e, Sm *sm)
{
    sm->status &= ~SM_ST_IRQ_READ; /* write open only during the copy */
    sm->w_open = 0;
    long latest = sm->l = sm->w;
    if (sm->r_open && sm->r != latest)
        sm->w = 3 - latest - sm->r;
    else
        sm->w = latest == 0 ? 1 : 0;
    sm->status |= SM_ST_IRQ_WRITE;
    if (sm_sync(e, sm) < 0)
        return -1;
    return sm_store(sm);
}

#endif
