/* Compiled servo substep loop: the same arithmetic as ecatsim.device.servo.Servo.run,
 * operation for operation, so both give bit-identical results (built with
 * -ffp-contract=off: no fused multiply-add). Optional: without a compiler the pure-Python
 * loop runs. The flux (d) axis is not here: Servo.run uses this loop only while the flux
 * axis carries no current.
 *
 * run(n, kind, ref, v_ff, window, i_trip, index, state, params)
 *   state  = (angle, omega, iq, iq_integ, integ, iq_ref)
 *   params = (dt, ppr, kt, load, viscous, coulomb, inertia, vmax, resistance, decay,
 *             lim, vlim, vel_kp, vel_ki, pos_kp, cur_kp, cur_ki)
 * returns (done, why, angle, omega, iq, iq_integ, integ, iq_ref)
 *
 * Ref: TMC8670 §5.1.7-5.1.10; docs/decisions.md D15, P2.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>

#include "_servo_loop.h"

static int floats(PyObject *tuple, double *out, Py_ssize_t n, const char *what)
{
    if (!PyTuple_Check(tuple) || PyTuple_GET_SIZE(tuple) != n) {
        PyErr_Format(PyExc_TypeError, "%s: expected a tuple of %zd floats", what, n);
        return -1;
    }
    for (Py_ssize_t i = 0; i < n; i++) {
        out[i] = PyFloat_AsDouble(PyTuple_GET_ITEM(tuple, i));
        if (out[i] == -1.0 && PyErr_Occurred())
            return -1;
    }
    return 0;
}

static PyObject *run(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    if (nargs != 9) {
        PyErr_SetString(PyExc_TypeError, "run() takes 9 arguments");
        return NULL;
    }
    long n = PyLong_AsLong(args[0]);
    long kind = PyLong_AsLong(args[1]);
    double ref = PyFloat_AsDouble(args[2]);
    double v_ff = PyFloat_AsDouble(args[3]);
    double window = PyFloat_AsDouble(args[4]);
    double i_trip = PyFloat_AsDouble(args[5]);
    int index = PyObject_IsTrue(args[6]);
    if (PyErr_Occurred())
        return NULL;
    double s[N_STATE], p[N_PARAMS];
    if (floats(args[7], s, N_STATE, "state") < 0 || floats(args[8], p, N_PARAMS, "params") < 0)
        return NULL;
    int why = STOP_NONE;
    long done = servo_loop(n, kind, ref, v_ff, window, i_trip, index, s, p, &why);
    return Py_BuildValue("(lidddddd)", done, why, s[0], s[1], s[2], s[3], s[4], s[5]);
}

static PyMethodDef methods[] = {
    {"run", (PyCFunction)(void (*)(void))run, METH_FASTCALL, "Servo substeps (see Servo.run)."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_servo", "Compiled servo substep loop.", -1, methods,
    NULL, NULL, NULL, NULL,
};

PyMODINIT_FUNC PyInit__servo(void)
{
    return PyModule_Create(&module);
}
