"""Gymnasium environments: drive the ego through roadsynth's naturalistic SUMO traffic (docs/envs.md).

Importing this package registers ``roadsynth/Highway-v0``, ``roadsynth/Urban-v0`` and ``roadsynth/Scenario-v0``
(``gymnasium.make("roadsynth/Scenario-v0", scenario=NAME_OR_PATH)``); ``perception=MODEL`` adds perception in the
loop (:class:`pipeline.envs.perception.PerceivedFeatures`, docs/closedloop.md).
"""

from gymnasium.envs.registration import register, registry

from pipeline.envs.env import RoadsynthEnv
from pipeline.envs.meta import MetaAction, MetaActions
from pipeline.envs.options import EnvOptions, RewardWeights

# perception=DETECTOR (an .onnx file, a model folder, or an object with predict) wraps the env in PerceivedFeatures
# (docs/closedloop.md).
for _id, _entry, _kwargs in (
        ("roadsynth/Highway-v0", "pipeline.envs.perception:make_env", {"scenario": "highway"}),
        ("roadsynth/Urban-v0", "pipeline.envs.perception:make_env", {"scenario": "urban"}),
        ("roadsynth/Scenario-v0", "pipeline.envs.perception:make_env", {})):
    if _id not in registry:
        register(id=_id, entry_point=_entry, kwargs=_kwargs)

__all__ = ["EnvOptions", "MetaAction", "MetaActions", "RewardWeights", "RoadsynthEnv"]
