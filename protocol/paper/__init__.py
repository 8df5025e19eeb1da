"""The paper's suite: Paillier linear forms, Veugen's DGK comparison, homomorphic gates, the
proof that Bob's Paillier key is fit, Bob's keys, its two machines.
"""
