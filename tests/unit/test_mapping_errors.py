"""The mapping's refusals name the offending field (control/mapping.py): a non-finite input
never becomes a drone command, and the error says which input it was."""

import math

import pytest

from ardrone_nmpc.control.mapping import MappingError, vz_reference_mps


@pytest.mark.parametrize("args, name", [((math.nan, 0.0, 0.065), "vz_est_mps"),
                                        ((0.0, math.inf, 0.065), "zacc_mps2"),
                                        ((0.0, 0.0, -math.inf), "dt_s")])
def test_a_non_finite_input_is_named(args, name):
    with pytest.raises(MappingError) as err:
        vz_reference_mps(*args)
    assert str(err.value).startswith(f"{name} must be finite, got ")


def test_a_zero_period_is_allowed_a_negative_one_is_not():
    assert vz_reference_mps(0.3, 5.0, 0.0) == 0.3
    with pytest.raises(MappingError) as err:
        vz_reference_mps(0.3, 5.0, -0.01)
    assert str(err.value) == "dt_s must be >= 0, got -0.01"


@pytest.mark.parametrize("field", ["vz_ref_mps", "phi_rad", "theta_rad", "psirate_radps"])
def test_map_to_pcmd_names_the_non_finite_field(field):
    from ardrone_nmpc.control.mapping import map_to_pcmd
    from ardrone_nmpc.core.types import AttitudeCommand

    values = dict(vz_ref_mps=0.1, phi_rad=0.01, theta_rad=-0.01, psirate_radps=0.2)
    values[field] = math.nan
    with pytest.raises(MappingError) as err:
        map_to_pcmd(AttitudeCommand(**values))
    assert str(err.value) == f"{field} must be finite, got nan"
