"""ConAg in the formats of robotics tools: Foxglove's well-known schemas (issue 34).

* `convert`: bus messages to Foxglove messages (`Translator`, the pure core): the world as a
  `SceneUpdate`, agent poses as `FrameTransforms`, sector sensors as `LaserScan`s, maps as
  `Grid`s, behaviours and stalls as `Log`, progress as JSON with a JSON schema;
* `live`: the shell that serves those channels over the Foxglove WebSocket protocol
  (`conag view --foxglove`, `conag run --foxglove`).

A recording gets the same channels beside its msgpack ones: `conag.recording.recorder`
feeds every message it writes through a `Translator` (`McapRecorder(derive=...)`).
The topics and what each holds: docs/how-to/foxglove.md.
"""
