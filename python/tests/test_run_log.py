"""Run logs read by an independent reader (docs/design.md §12): Python's
`mcap` package opens a sim's run.mcap; the channels, schemas and message
counts are the ones the report says the plant wrote; the JSON channels
decode; the report's summary is the file's metadata."""

import json

import pytest
from mcap.reader import make_reader

from conftest import one_loop_at_a_time, run_cli


def test_a_sims_run_log_reads_in_python(tmp_path, cli):
    out = tmp_path / "sim"
    with one_loop_at_a_time():
        r = run_cli(
            cli, "sim", "--model", "firmware/vectors/default.tnet", "--duration", "1.5",
            "--out", str(out),
        )
    assert r.returncode == 0, r.stderr
    report = json.loads((out / "report.json").read_text())
    written = report["plant"]["generations"][0]["runlog"]

    counts, schemas, errors = {}, {}, []
    with open(out / "run.mcap", "rb") as f:
        reader = make_reader(f)
        for schema, channel, message in reader.iter_messages():
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
            schemas[channel.topic] = (schema.name, schema.encoding, channel.message_encoding)
            if channel.topic == "/tracking":
                t = json.loads(message.data)
                assert len(t["actual_m"]) == 3
                if t["error_mm"] is not None:
                    errors.append(t["error_mm"])
        metadata = {m.name: m.metadata for m in reader.iter_metadata()}

    assert counts == written["messages"]
    assert written["dropped"] == 0
    assert schemas["/robot/scene"] == ("foxglove.SceneUpdate", "protobuf", "protobuf")
    assert schemas["/tf"] == ("foxglove.FrameTransforms", "protobuf", "protobuf")
    assert schemas["/log"] == ("foxglove.Log", "protobuf", "protobuf")
    assert schemas["/tensions"] == ("tendril.Tensions", "jsonschema", "json")
    assert counts["/tensions"] == report["plant"]["generations"][0]["steps"]
    # The loop tracked: most steps are within a millimetre of the setpoint.
    assert errors and sorted(errors)[len(errors) // 2] < 1.0
    assert float(metadata["report"]["rms_tracking_error_mm"]) == pytest.approx(
        report["rms_tracking_error_mm"], rel=1e-12
    )
