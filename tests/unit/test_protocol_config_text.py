"""The configuration dump's text: what the loopback drone writes, the client reads back."""

from hypothesis import example, given
from hypothesis import strategies as st

from ardrone_nmpc.protocol.config_text import format_config_text, parse_config_text

KEY = st.from_regex(r"[a-z]{1,8}:[a-z_]{1,20}", fullmatch=True)
# printable ASCII, trimmed; '=' included: a value may hold one (the key ends at the first)
VALUE = st.from_regex(r"[!-~]([ -~]{0,18}[!-~])?", fullmatch=True)


@given(st.dictionaries(KEY, VALUE, max_size=20))
@example({"video:codec_opts": "a=b"})   # the case that separates the first '=' from the last
def test_what_the_drone_writes_reads_back_unchanged(values):
    assert parse_config_text(format_config_text(values)) == values


def test_a_value_holding_an_equals_sign_keeps_it():
    text = "video:codec_opts = a=b\nnetwork:ssid = =x=\n"
    assert parse_config_text(text) == {"video:codec_opts": "a=b", "network:ssid": "=x="}


def test_a_dump_as_the_firmware_sends_it():
    text = ("general:num_version_soft = 2.4.8\ncontrol:euler_angle_max = 0.52\n"
            "control:outdoor = FALSE\n\nnot a key line\n = orphan value\n\x00")
    assert parse_config_text(text) == {"general:num_version_soft": "2.4.8",
                                       "control:euler_angle_max": "0.52",
                                       "control:outdoor": "FALSE"}
