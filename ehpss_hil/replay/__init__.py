"""Replaying a logged run through the controller, offline (:mod:`.engine`)."""
