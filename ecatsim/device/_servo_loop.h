/* The servo substep loop shared by _servo.c (Servo.run) and _drive.c (Drive steady
 * cycle): the same arithmetic as ecatsim.device.servo.Servo._run, operation for
 * operation (compiled with -ffp-contract=off: no fused multiply-add).
 *   s = (angle, omega, iq, iq_integ, integ, iq_ref), updated in place
 *   p = (dt, ppr, kt, load, viscous, coulomb, inertia, vmax, resistance, decay, lim, vlim,
 *        vel_kp, vel_ki, pos_kp, cur_kp, cur_ki)
 * Returns the substeps done; *why_out says why it stopped early (STOP_NONE if it did not).
 * Ref: TMC8670 §5.1.7-5.1.10; docs/decisions.md D15, P2.
 */
#ifndef ECATSIM_SERVO_LOOP_H
#define ECATSIM_SERVO_LOOP_H
#include <math.h>

enum { TORQUE = 0, VELOCITY = 1, POSITION = 2 };
enum { STOP_NONE = 0, STOP_FOLLOWING = 1, STOP_OVERCURRENT = 2, STOP_INDEX = 3 };
#define N_STATE 6
#define N_PARAMS 17

static const double TWO_PI = 6.283185307179586; /* 2.0 * math.pi */

static inline double clamp(double x, double lo, double hi)
{
    return x < lo ? lo : x > hi ? hi : x;
}

static long servo_loop(long n, long kind, double ref, double v_ff, double window,
                       double i_trip, int index, double *s, const double *p, int *why_out)
{
    double angle = s[0], omega = s[1], iq = s[2], iq_integ = s[3], integ = s[4], iq_ref = s[5];
    const double dt = p[0], ppr = p[1], kt = p[2], load = p[3], viscous = p[4];
    const double coulomb = p[5], inertia = p[6], vmax_v = p[7], resistance = p[8];
    const double decay = p[9], lim = p[10], vlim = p[11], vel_kp = p[12], vel_ki = p[13];
    const double pos_kp = p[14], cur_kp = p[15], cur_ki = p[16];
    const double rpm = TWO_PI / 60.0;
    long done = 0;
    int why = STOP_NONE;
    while (done < n) {
        double out;
        if (kind == TORQUE) {
            out = ref;
        } else {
            double v_ref;
            if (kind == POSITION) {
                double err_p = ref - angle / TWO_PI * ppr;
                if (window != 0.0 && fabs(err_p) > window) {
                    why = STOP_FOLLOWING;
                    break;
                }
                v_ref = pos_kp * err_p + v_ff;
            } else {
                v_ref = ref;
            }
            v_ref = clamp(v_ref, -vlim, vlim);
            double err = v_ref - omega / rpm;
            out = vel_kp * err + integ;
            if (-lim < out && out < lim)
                integ += vel_ki * err * dt;
        }
        iq_ref = clamp(out, -lim, lim);
        double emf = kt * omega;
        double err_a = (iq_ref - iq) / 1000.0;
        double v = cur_kp * err_a + iq_integ + emf;
        if (-vmax_v < v && v < vmax_v)
            iq_integ += cur_ki * err_a * dt;
        v = clamp(v, -vmax_v, vmax_v);
        iq = (iq / 1000.0 * decay + (1.0 - decay) * (v - emf) / resistance) * 1000.0;
        if (iq_ref == 0.0 && omega == 0.0 && fabs(iq) < 1e-3)
            iq = iq_integ = 0.0;
        double torque = kt * iq / 1000.0;
        double drive = torque - load - viscous * omega;
        if (omega > 1e-9)
            drive -= coulomb;
        else if (omega < -1e-9)
            drive += coulomb;
        else if (fabs(drive) <= coulomb)
            drive = 0.0;
        else
            drive -= copysign(coulomb, drive);
        double next = omega + drive / inertia * dt;
        if (omega != 0.0 && ((next > 0) != (omega > 0)) && fabs(torque - load) <= coulomb)
            next = 0.0;
        double rev = index ? floor(angle / TWO_PI) : 0.0;
        omega = next;
        angle += omega * dt;
        done++;
        if (fabs(iq) > i_trip) {
            why = STOP_OVERCURRENT;
            break;
        }
        if (index && floor(angle / TWO_PI) != rev) {
            why = STOP_INDEX;
            break;
        }
    }
    s[0] = angle;
    s[1] = omega;
    s[2] = iq;
    s[3] = iq_integ;
    s[4] = integ;
    s[5] = iq_ref;
    *why_out = why;
    return done;
}
#endif
