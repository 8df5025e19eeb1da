"""Security parameters and their floor (112-bit security, NIST SP 800-57).

* Paillier and DGK moduli: at least 2048 bits.
* DGK subgroup order t: at least 224 bits, twice the security level, because the best known
  attack on the small-RSA-subgroup assumption runs in about 2^(t/2) operations.
* kappa: statistical blinding of the additive masks, at least 40 bits (statistical distance
  2^-kappa between the masked value's distributions for any two inputs).
* The EC back-end uses secp256k1 (about 128-bit security).

Anything weaker is refused with :class:`InsecureParametersError` unless the caller passes
``insecure_for_tests=True`` -- a name nobody types by accident.
"""

from __future__ import annotations

from dataclasses import dataclass

from protocol.errors import InsecureParametersError

MIN_MODULUS_BITS = 2048
MIN_DGK_T = 224
MIN_KAPPA = 40


@dataclass(frozen=True, slots=True)
class SecurityParameters:
    """The parameters in force for one run; validated on construction."""

    paillier_bits: int = 2048
    dgk_bits: int = 2048
    dgk_t: int = 224
    kappa: int = 40
    insecure_for_tests: bool = False

    def __post_init__(self) -> None:
        check_modulus_bits(self.paillier_bits, self.insecure_for_tests)
        check_modulus_bits(self.dgk_bits, self.insecure_for_tests)
        check_dgk_t(self.dgk_t, self.insecure_for_tests)
        check_kappa(self.kappa, self.insecure_for_tests)


def check_modulus_bits(bits: int, insecure_for_tests: bool = False) -> None:
    """Refuse an RSA-type modulus below 2048 bits."""
    if bits < MIN_MODULUS_BITS and not insecure_for_tests:
        raise InsecureParametersError(
            f"modulus of {bits} bits is below {MIN_MODULUS_BITS} (112-bit security)"
        )


def check_dgk_t(t: int, insecure_for_tests: bool = False) -> None:
    """Refuse a DGK subgroup order below 224 bits (t = 160 is only about 80-bit secure)."""
    if t < MIN_DGK_T and not insecure_for_tests:
        raise InsecureParametersError(f"DGK t = {t} is below {MIN_DGK_T} (112-bit security)")


def check_kappa(kappa: int, insecure_for_tests: bool = False) -> None:
    """Refuse statistical blinding below 40 bits."""
    if kappa < MIN_KAPPA and not insecure_for_tests:
        raise InsecureParametersError(f"kappa = {kappa} is below {MIN_KAPPA}")
