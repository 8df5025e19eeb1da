"""The compact suite (the default): OT products, millionaires and GMW on SoftSpokenOT, its
public plan and its two machines.
"""
