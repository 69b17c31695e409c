"""``coassist play`` on a network bind refuses a token anyone could guess (issue 37).

The probe ran ``coassist play --host 0.0.0.0 --token x``: the server started, its
websocket guarded by one character. A token guarding a non-loopback bind now needs
at least 16 characters and 64 bits by the estimate ``len · log2(distinct characters)``;
one made by coassist (128 random bits) and any token on a loopback bind still start.
"""

from __future__ import annotations

import math

import pytest
from typer.testing import CliRunner

pytest.importorskip("starlette", reason="coassist play needs the web extra (pip install 'coassist[web]')")

from coassist.cli import app  # noqa: E402
from coassist.play import server as play_server  # noqa: E402
from coassist.play.server import MIN_TOKEN_BITS, MIN_TOKEN_CHARS, PlayServer, check_token, new_token  # noqa: E402
from coassist.play.session import PlayConfig, PlaySession  # noqa: E402


@pytest.fixture
def served(monkeypatch):
    """PlayServer.run replaced: records the server the CLI would serve, instead of serving until Ctrl+C."""
    started: list[PlayServer] = []

    def run(self: PlayServer) -> None:
        started.append(self)
        self._shutdown_session()

    monkeypatch.setattr(play_server.PlayServer, "run", run)
    return started


def _play(tmp_path, *args: str):
    return CliRunner().invoke(app, ["play", "--out", str(tmp_path), "--no-open", "--port", "0", *args])


WEAK = [
    "x",
    "s3cret",
    "0123456789abcde",
    "aaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaa",
    "abababababababababababababababab",
    "passwordpassword",
]


@pytest.mark.parametrize("token", WEAK)
def test_a_weak_token_on_a_network_bind_is_one_line_and_nothing_serves(tmp_path, served, token):
    res = _play(tmp_path, "--host", "0.0.0.0", "--token", token)
    assert res.exit_code == 2 and "Traceback" not in res.output, res.output
    lines = [ln for ln in res.output.splitlines() if ln.startswith("error:")]
    assert len(lines) == 1 and "--token" in lines[0] and f"at least {MIN_TOKEN_CHARS} characters" in lines[0], (
        res.output
    )
    assert served == []


def test_the_bound_is_length_times_log2_of_distinct_characters():
    """By hand: 16 distinct characters give 16·4 = 64 bits (the least accepted); 15 distinct of 16, 62.5 (shown as 63)."""
    check_token("0123456789abcdef", "0.0.0.0")
    assert 16 * math.log2(15) < MIN_TOKEN_BITS <= 16 * math.log2(16)
    with pytest.raises(ValueError, match="got 16 characters, 63 bits"):
        check_token("0123456789abcdee", "0.0.0.0")
    with pytest.raises(ValueError, match="needs a token"):
        check_token(None, "192.168.1.10")
    with pytest.raises(ValueError, match=r"--token may hold only .* got '&'"):
        check_token("a&b", "127.0.0.1")


def test_the_generated_token_and_loopback_binds_still_start(tmp_path, served):
    res = _play(tmp_path, "--host", "0.0.0.0")  # no --token: coassist makes one
    assert res.exit_code == 0, res.output
    token = served[-1].token
    assert len(token) == 22 and f"?token={token}" in res.output.replace("\n", "")
    check_token(token, "0.0.0.0")
    for _ in range(200):  # every generated token clears the bound (128 random bits, 22 characters)
        check_token(new_token(), "::")
    res = _play(tmp_path, "--token", "x")  # loopback: this machine only, any token
    assert res.exit_code == 0, res.output
    strong = "Tq7-xR2_vLm9.Kp4~Zs8"
    res = _play(tmp_path, "--host", "0.0.0.0", "--token", strong)
    assert res.exit_code == 0 and served[-1].token == strong, res.output


def test_the_server_itself_refuses_a_weak_token(tmp_path):
    """Not only the CLI: a PlayServer built in code on a network bind checks its token too."""
    session = PlaySession(PlayConfig(user="alice", out=tmp_path))
    try:
        with pytest.raises(ValueError, match=r"--token is too weak for --host 0\.0\.0\.0"):
            PlayServer(session, host="0.0.0.0", port=0, token="x")
    finally:
        session.close()
