"""Plant identification (``ehpss-hil identify``): a bounded excitation around the PI loop
(:mod:`.excitation`, :mod:`.experiment`), a least-squares fit of params.yaml's plant keys with
intervals (:mod:`.fit`), and its report (:mod:`.report`). scipy is needed (the ``identify``
extra); the daemon imports nothing from here."""
