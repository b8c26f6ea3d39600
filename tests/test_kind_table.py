"""KindTable (host/kinds/table.py): ids, traits and dispatch generated from declarations."""
import pytest

from gpiscl.host.kinds.table import Kind, KindTable
from gpiscl.host.schema import Context, Field, Number, Record


def table():
    return KindTable("toy", "TOY", [
        Kind("plain", Record({"a": Field(Number(ge=0), 1.0)}), traits={"smooth": True, "order": 0}),
        Kind("rough", Record({}), traits={"smooth": False, "order": 2}),
    ], traits=("smooth", "order"))


def test_ids_are_positions_and_enum_and_traits_are_generated():
    t = table()
    assert (t.id("plain"), t.id("rough")) == (0, 1)
    assert t.c_enum() == ["#define TOY_PLAIN 0", "#define TOY_ROUGH 1", "#define TOY_COUNT 2"]
    smooth, order = t.c_traits()
    assert smooth == "#define TOY_IS_SMOOTH(k) ((k) == TOY_PLAIN)"
    assert order == "#define TOY_ORDER(k) ((k) == TOY_PLAIN ? 0 : ((k) == TOY_ROUGH ? 2 : 0))"
    assert "case TOY_ROUGH: return rough_eval(x);" in t.c_dispatch("eval", "float", "float x", "x")


def test_schema_variants_follow_the_table_and_temporary_kinds_leave_no_trace():
    t = table()
    ctx = Context("s.json", ".")
    assert t.schema.resolve({"type": "plain"}, "m", ctx) == {"type": "plain", "a": 1.0}
    with t.registered(Kind("toy3", Record({}), traits={"smooth": True, "order": 1})):
        assert t.id("toy3") == 2 and "toy3" in t.schema.variants
    assert "toy3" not in t.names and "toy3" not in t.schema.variants


def test_a_kind_must_state_every_trait_and_have_its_device_file():
    t = table()
    with pytest.raises(ValueError, match="missing \\['order'\\]"):
        t.register(Kind("bad", traits={"smooth": True}))
    with pytest.raises(ValueError, match="no device file"):
        t.register(Kind("bad", traits={"smooth": True, "order": 0}, device_file="lib/nope.h"))
    with pytest.raises(ValueError, match="declared twice"):
        t.register(Kind("plain", traits={"smooth": True, "order": 0}))


def test_void_dispatch_named_dispatch_and_a_second_table_of_a_prefix():
    t = table()
    void = t.c_dispatch("fill", "void", "float* x", "x")
    assert "case TOY_PLAIN: plain_fill(x); return;" in void and "default: return;" in void
    assert t.c_dispatch("eval", "float", "float x", "x", name="toy_of").startswith(
        "inline float toy_of(int kind, float x)")
    ops = KindTable("toy op", "TOY", [Kind("join", traits={})], first_id=16, schema=t.schema)
    assert ops.id("join") == 16 and ops.c_enum(count=False) == ["#define TOY_JOIN 16"]
    ops.register(Kind("meet", Record({}), traits={}))
    assert "meet" in t.schema.variants     # one scene key, two tables
