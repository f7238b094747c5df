"""Output sinks: the Rerun recording / live stream, read-back, inspect, record-all, resim.

``attach(player, scene, options)`` is the hook the CLI calls (see ``recorder.attach``); the
CLI commands are ``inspect.main_inspect``, ``record_all.main_record_all`` and
``resim.main_resim``. rerun is imported lazily: importing this package stays cheap.
"""
from __future__ import annotations

from magica_py.sinks.base import (ClothFrame, ClothTopology, ColliderShapes, FrameData, LogToggles, NullSink,
                                  SceneStatics, Sink, SnapshotProvider)
from magica_py.sinks.recorder import Recorder, SinkOptions, attach

__all__ = ["attach", "Recorder", "SinkOptions", "Sink", "NullSink", "SnapshotProvider", "ClothTopology",
           "ClothFrame", "ColliderShapes", "FrameData", "LogToggles", "SceneStatics"]
