"""Plant emulator: the EHPSS (servo valve + cylinder + sensors) with injectable faults.

It imports ``ehpss_hil.physics`` and the frame codec, never the controller. Importing the
program holds BLAS to one thread before numpy loads (:func:`ehpss_hil.blas.limit_blas_env`).
"""

from ehpss_hil.blas import limit_blas_env

limit_blas_env()
