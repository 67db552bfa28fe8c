"""A part of a model's C compiled while the rest is still eliminated
(modelgen/codegen/parts.py): the library is the one built without it, bit for
bit; an early object whose part the final file changed is discarded; a build
refused after its elimination leaves no compile running and no files."""
from __future__ import annotations

import pytest

import modelgen.codegen.pipeline as pipeline
from modelgen.codegen import parts
from modelgen.codegen.compilers import core_count
from modelgen.codegen.options import BuildOptions
from modelgen.errors import ModelError
from modelgen.model.chains import spatial_chain

pytestmark = pytest.mark.skipif(core_count() < 2, reason="one core: the C is one part")


def _build(tmp_path, n: int, derivatives: bool, early: bool, monkeypatch):
    with monkeypatch.context() as m:
        if not early:
            m.setattr(pipeline._EarlyStart, "__call__", lambda self, built: None)
        g = pipeline.generate(spatial_chain(n).spec(), tmp_path / f"{n}-{derivatives}-{early}",
                              force=True, options=BuildOptions(derivatives=derivatives))
    return g.manifest


@pytest.mark.parametrize("n, derivatives, early", [(6, False, [2, 3]), (7, True, [2, 3, 4])])
def test_the_early_parts_give_the_same_library(tmp_path, monkeypatch, n, derivatives, early):
    with_early = _build(tmp_path, n, derivatives, True, monkeypatch)
    without = _build(tmp_path, n, derivatives, False, monkeypatch)
    assert with_early["early_parts"] == early and without["early_parts"] == []
    assert with_early["module_sha256"] == without["module_sha256"]
    assert with_early["compile_commands"] == without["compile_commands"]


def test_an_early_part_the_final_file_changed_is_compiled_again(tmp_path, monkeypatch):
    started = []
    real = parts.start

    def start_changed(directory, name, sources, part, command):
        # the part as a later stage could change it: one more line in its block
        if part != 2:
            return real(directory, name, sources, part, command)
        marker = "#if !defined(MG_PART) || MG_PART == 2\n"
        changed = dict(sources, **{f"{name}.c": sources[f"{name}.c"].replace(
            marker, marker + "static const int mg_changed_later = 1;\n", 1)})
        started.append(real(directory, name, changed, part, command))
        return started[-1]
    monkeypatch.setattr(parts, "start", start_changed)
    manifest = _build(tmp_path, 6, False, True, monkeypatch)
    monkeypatch.undo()
    assert started and started[0] is not None
    assert manifest["early_parts"] == [3]                # 2 discarded, compiled again
    assert manifest["module_sha256"] == _build(tmp_path, 6, False, False,
                                               monkeypatch)["module_sha256"]
    assert not started[0].tmp.exists()


def test_a_build_refused_after_elimination_stops_its_early_part(tmp_path, monkeypatch):
    started = []
    real = parts.start
    monkeypatch.setattr(parts, "start", lambda *a: started.append(real(*a)) or started[-1])
    spec = spatial_chain(6).spec()
    with_all = pipeline.generate(spec, tmp_path / "ok", force=True)
    total = sum(o["after_cse"] for o in with_all.ops.values())
    started.clear()
    with pytest.raises(ModelError, match="operations after CSE"):
        # over the budget as a whole, not by the rhs alone: the early part starts
        pipeline.generate(spec, tmp_path / "refused", force=True, max_operations=total // 2)
    assert started and started[0] is not None
    assert started[0].proc.poll() is not None            # not left running
    assert not list((tmp_path / "refused").glob(".build-*"))
    assert not list((tmp_path / "refused").glob("*.c"))


def test_part_text_keeps_the_common_lines_and_the_part():
    src = ("head\n#if !defined(MG_PART) || MG_PART == 1\none\n#endif /* MG_PART 1 */\n"
           "#if !defined(MG_PART)\nwhole\n#endif\n"
           "#if !defined(MG_PART) || MG_PART == 2\ntwo\n#if X\nx\n#endif\n#endif /* MG_PART 2 */\n")
    assert parts.part_text(src, 1) == ("head\n#if !defined(MG_PART) || MG_PART == 1\none\n"
                                       "#endif /* MG_PART 1 */\n#if !defined(MG_PART)\n"
                                       "whole\n#endif\n")
    assert "two" in parts.part_text(src, 2) and "one" not in parts.part_text(src, 2)
    # blocks that do not pair up: nothing is assumed
    assert parts.part_text(src.replace("#endif /* MG_PART 1 */\n", ""), 2) is None
    assert parts.part_text("#if !defined(MG_PART) || MG_PART == 1\n", 2) is None


def test_a_failed_early_compile_is_a_build_error_with_its_output(tmp_path):
    """The early part's own compile failing (what run_commands reports for the
    others): the command, the compiler's output and its exit status."""
    from modelgen.errors import BuildError
    sources = {"m.c": "int x;\n", "m.h": ""}
    command = ["sh", "-c", "echo 'm.c:1: error: boom'; exit 3", "-o", "m_2.o"]
    early = parts.start(tmp_path, "m", sources, 2, command)
    assert early is not None and early.matches(sources, "m", command)
    with pytest.raises(BuildError, match="C compiler failed") as info:
        early.finish(tmp_path / "m_2.o")
    assert "boom" in str(info.value) and info.value.returncode == 3
    assert info.value.command == command
    assert not early.tmp.exists() and not (tmp_path / "m_2.o").exists()


def test_an_early_part_that_cannot_start_leaves_nothing(tmp_path):
    """A compiler that cannot run: no early part (the build then reports it, see
    tests/test_build_cache.py) and no directory left."""
    assert parts.start(tmp_path, "m", {"m.c": ""}, 2, [str(tmp_path / "no-such-cc")]) is None
    assert not list(tmp_path.glob(".build-*"))


def test_a_part_whose_text_cannot_be_told_is_never_kept(tmp_path):
    """Blocks that do not pair up: part_text cannot say what the part reads, so
    the early object is not used even when the two files are the same."""
    sources = {"m.c": "#if !defined(MG_PART) || MG_PART == 1\nint x;\n", "m.h": ""}
    command = ["sh", "-c", "exit 0", "-o", "m_2.o"]
    early = parts.start(tmp_path, "m", sources, 2, command)
    assert early is not None and not early.matches(sources, "m", command)
    assert not early.tmp.exists()
