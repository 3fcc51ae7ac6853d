/* The module slots every hand-written extension declares (multi-phase init, PEP 489): it
 * needs the GIL (its state is in static variables and it swaps object pointers without
 * locks), so on a free-threaded interpreter importing it would turn the GIL back on; the
 * loader (ecatsim/compiled.py) does not import it there. It keeps one state per process,
 * so only the main interpreter loads it. */
#ifndef ECATSIM_MODULE_H
#define ECATSIM_MODULE_H
#include <Python.h>

#ifdef Py_mod_gil
#define ECATSIM_SLOT_GIL {Py_mod_gil, Py_MOD_GIL_USED},
#else
#define ECATSIM_SLOT_GIL
#endif

#ifdef Py_mod_multiple_interpreters
#define ECATSIM_SLOT_INTERP \
    {Py_mod_multiple_interpreters, Py_MOD_MULTIPLE_INTERPRETERS_NOT_SUPPORTED},
#else
#define ECATSIM_SLOT_INTERP
#endif

/* The slots of a module whose exec function is ``exec``. */
#define ECATSIM_MODULE_SLOTS(exec) \
    {{Py_mod_exec, (void *)(exec)}, ECATSIM_SLOT_GIL ECATSIM_SLOT_INTERP {0, NULL}}

#endif
