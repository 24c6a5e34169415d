"""Fixtures of the deploy tests (helpers in deploy_helpers.py): one calibrated result folder per shipped scene,
computed once per session."""

from types import SimpleNamespace

import pytest

from vision_calib.deploy import CalibratedRobot

from deploy_helpers import SCENES, calibrate


@pytest.fixture(scope="session")
def results(tmp_path_factory):
    """{scene name: SimpleNamespace(name, run (SyntheticRun), folder, robot (CalibratedRobot))}, filled lazily."""
    cache = {}

    class Lazy(dict):
        def __missing__(self, name):
            run, folder = calibrate(name, tmp_path_factory.mktemp(name))
            cache[name] = SimpleNamespace(name=name, run=run, folder=folder, robot=CalibratedRobot.load(folder))
            self[name] = cache[name]
            return cache[name]

    return Lazy()


@pytest.fixture(scope="session", params=SCENES)
def result(request, results):
    """The calibrated result of each shipped scene in turn."""
    return results[request.param]
