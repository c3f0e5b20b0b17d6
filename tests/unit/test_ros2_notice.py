"""The launcher's notice for ROS 2 tools: a plain run names the router to connect to; a --secure run, where a
plain connection cannot open, names a role's configuration to join with instead."""

from __future__ import annotations

import logging
from pathlib import Path

import pytest

from reconswarm_bringup.outcome import ros2_notice


def test_plain_run_names_the_router(caplog: pytest.LogCaptureFixture) -> None:
    with caplog.at_level(logging.INFO):
        ros2_notice("tcp/127.0.0.1:7000", 17)
    text = caplog.text
    assert "domain 17 on the Zenoh router tcp/127.0.0.1:7000" in text
    assert "ZENOH_CONFIG_OVERRIDE='connect/endpoints=[\"tcp/127.0.0.1:7000\"]'" in text
    assert "ZENOH_SESSION_CONFIG_URI" not in text


def test_secure_run_names_a_role_configuration_not_a_plain_connection(caplog: pytest.LogCaptureFixture,
                                                                       tmp_path: Path) -> None:
    with caplog.at_level(logging.INFO):
        ros2_notice("tls/127.0.0.1:7000", 3, tmp_path / "secrets")
    text = caplog.text
    assert f"ZENOH_SESSION_CONFIG_URI={tmp_path / 'secrets' / 'observer.json5'}" in text
    assert "ROS_DOMAIN_ID=3" in text and "a plain connection is refused" in text
    assert "ZENOH_CONFIG_OVERRIDE" not in text  # (it would point the tool at a router that refuses it)
