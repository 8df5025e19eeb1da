"""Cryptographic primitives: Paillier, DGK, secp256k1, primes, noise pools, and the security
parameters every one of them checks.
"""
