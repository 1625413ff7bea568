"""The contract's documentation and machine-readable schemas come from common/schema.py and cannot drift."""

import json

import msgspec

from common import schema
from hri import wiredoc


def test_docs_wire_md_tables_match_the_schemas():
    text = wiredoc.DOC.read_text()
    assert wiredoc.missing_tables(text) == [], "a struct on the wire has no generated table in docs/wire.md"
    assert wiredoc.render(text) == text, "docs/wire.md is stale: run `python -m hri.wiredoc`"


def test_every_field_of_every_wire_struct_is_in_its_table():
    text = wiredoc.DOC.read_text()
    for name, cls in wiredoc.documented_structs().items():
        section = text.split(f"<!-- fields: {name} -->", 1)[1].split("<!-- /fields -->", 1)[0]
        envelope = set(schema.Sample.__struct_fields__) if cls is not schema.Sample else set()
        for field in set(cls.__struct_fields__) - envelope:
            assert f"| `{field}` |" in section, (name, field)


def test_a_changed_field_makes_the_check_fail(tmp_path, monkeypatch):
    doc = tmp_path / "wire.md"
    doc.write_text(wiredoc.DOC.read_text().replace("| `seq` | int ≥ 0 |", "| `seq` | int |", 1))
    monkeypatch.setattr(wiredoc, "DOC", doc)
    assert wiredoc.main(["--check"]) == 1
    assert wiredoc.main([]) == 0 and wiredoc.main(["--check"]) == 0
    assert doc.read_text() == wiredoc.DOC.read_text() and "| `seq` | int ≥ 0 |" in doc.read_text()


def test_json_schema_of_each_sample_describes_its_fields():
    for cls in schema.ALL_SAMPLES:
        js = wiredoc.json_schema(cls)
        json.dumps(js)  # serialisable, for an MCAP schema record
        body = js["$defs"][cls.__name__]
        assert set(body["properties"]) == set(cls.__struct_fields__)
        assert set(body["required"]) == set(cls.required_fields())
    unit = wiredoc.json_schema(schema.Detections)["$defs"]["DetectedObject"]["properties"]["score"]
    assert unit["minimum"] == 0.0 and unit["maximum"] == 1.0


def test_type_text_renders_constraints_as_the_doc_reads():
    assert wiredoc.type_text(schema.UnitFloat)[0] == "0–1"
    assert wiredoc.type_text(schema.Finite)[0] == "float"
    assert wiredoc.type_text(schema.Box)[0] == "[float] length 4"
    assert wiredoc.type_text(schema.Optional[schema.Ray])[0] == "Ray\\|nil"
    assert wiredoc.type_text(msgspec.structs.fields(schema.AudioChunk)[-3].type)[0] == "int 1–32"
