"""Oblivious transfer for the lean comparison suite (sans-IO, pure).

Theory of operation
-------------------
Two drones that meet run a *one-time setup* (:mod:`.setup`): kappa base OTs on secp256k1
(:mod:`.base`) turn into punctured GGM trees (:mod:`.pprf`), one per block of a secret
kappa-bit Delta held by the *Delta holder* (Alice); the *chooser* (Bob) knows every leaf, Alice
every leaf but the one at her Delta block.  Both cache the result per peer.  kappa = 112 by
default (the project's security level), 128 on request.

Every later run extends it (:mod:`.extension`, SoftSpokenOT by Roy, CRYPTO 2022): the leaves are
expanded with a PRG keyed by the run's nonce into a small-field VOLE per block, which together
are IKNP's correlation q_i = t_i xor c_i Delta (Ishai, Kilian, Nissim, Petrank 2003).  Bob sends
(blocks - 1) bits per OT -- 9 with the default blocks of at most 12 bits, against IKNP's
kappa -- and hashing gives
*random OTs*: Alice holds keys (K_i^0, K_i^1), Bob a random choice c_i and K_i^{c_i}.

Random OTs are consumed in a fixed public order (the run's plan) by the
sub-protocols built on them: OT-based products (:mod:`protocol.compact.products`), the comparison
leaves (:mod:`protocol.compact.millionaire`) and Beaver triples (:mod:`protocol.compact.gmw`).
"""
