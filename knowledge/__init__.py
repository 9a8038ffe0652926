"""The representation layer (Wixson 1991, sections 2.2 and 4): object types, relation volumes,
confidence intervals, Highest-Impact-First bookkeeping and the evidence store.

Pure numpy + stdlib: nothing here imports MuJoCo or dm_control, so any robot can use it.
"""
