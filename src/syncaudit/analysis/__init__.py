"""Part A of the method on extracted columns: pairing, Eq. 1-6, the delay controller.

`pairing` pairs frames with triggers and revolutions, `offset` finds the host-sensor
clock offset, `sync` computes one camera's audit, `stats` holds Eq. 5/6 (`rolling`: over a
window, pandas' results without pandas), `controller`
and `replay` run the self-adaptive delay correction. `stamps` keeps epoch stamps int64.
"""
