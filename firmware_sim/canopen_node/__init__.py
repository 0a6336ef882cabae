"""The emulated CANopen nodes of ``protocol: cia408``: a CiA 408 servo valve and a CiA 406
linear encoder (docs/hardware.md). :mod:`.node` is the CiA 301 slave (NMT, SDO server, PDOs on
SYNC, heartbeat, EMCY), :mod:`.store` its object values and SDO access checks, :mod:`.pdo` the
PDO mappings, :mod:`.device` the CiA 408 device state machine, :mod:`.valve` and
:mod:`.encoder` the two profiles."""
