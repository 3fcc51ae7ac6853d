"""TMCM-1311 closed-loop stepper module emulated over TMCL (``ecatsim tmcl``).

Ref: TMCM-1311 TMCL firmware manual V1.11.
"""
