"""Plant emulator: the EHPSS (servo valve + cylinder + sensors) with injectable faults.

It imports ``ehpss_hil.physics`` and the frame codec, never the controller.
"""
