"""Hostile names in every exporter (issue 12, item 1): nothing a user controls (file names,
material names, source specs, names read from a fit file header) may end up in generated code
or markup unescaped.

For each exporter and each payload the generated file is parsed with the target language's
own parser (Python ``ast``/``tokenize`` and actual execution, ElementTree, ``json``,
glslangValidator) and checked: it parses, the payload's marker appears only inside string
constants / escaped text, and the readable name round-trips exactly where the format stores it.
"""

from __future__ import annotations

import ast
import io
import json
import os
import subprocess
import sys
import textwrap
import tokenize
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

import brdffit
from brdffit.cli import main
from brdffit.errors import ExportError
from brdffit.export import export
from brdffit.export import glsl as GL
from brdffit.export import mitsuba as M
from tests.export.test_glsl import _npf

MARK = "PWNMARK"  # every payload carries it: it must never be found outside string literals

#: name -> payload (material names may hold anything; ``/`` and NUL are dropped for file names)
PAYLOADS = {
    "python-quotes": f'x");open("INJECTED","w").write("{MARK}");("',
    "single-quotes": f"a'b''' \"\"\" {MARK}'",
    "newline": f"a\nimport os; os.system('touch INJECTED') # {MARK}\n#",
    "script-tag": f"</script><script>alert('{MARK}')</script>",
    "cdata": f"]]><evil a='{MARK}'/><![CDATA[",
    "comments": f"*/ void main() {{}} /* --> <!-- {MARK} --- -->//",
    "template": f"{{{{7*7}}}} {{0}} %s ${{{MARK}}}",
    "backslash": f"C:\\dir\\{MARK}\\",
    "non-ascii": f"金 銀 ü \u2028 \u202e {MARK}",
    "traversal": f"../../{MARK}/../etc/passwd",
    "nul": f"a\x00b{MARK}",
}
FILE_PAYLOADS = {k: v.replace("/", "_").replace("\x00", "_") for k, v in PAYLOADS.items()}


def _named(model, name):
    model.name = name
    model.source = name
    return model


def _gold(name):
    return _named(brdffit.synthetic("gold-ggx"), name)


def _sgd(name):
    return _named(brdffit.synthetic("sgd-paint"), name)


# ------------------------------------------------------------------------------------------
# checkers, one per language
# ------------------------------------------------------------------------------------------
_CODE_TOKENS = {tokenize.NAME, tokenize.OP, tokenize.NUMBER, tokenize.COMMENT,
                tokenize.ERRORTOKEN}
_CODE_TOKENS |= {getattr(tokenize, t) for t in ("FSTRING_START", "FSTRING_MIDDLE", "FSTRING_END")
                 if hasattr(tokenize, t)}


class _Blank(ast.NodeTransformer):
    def visit_Constant(self, node):
        return ast.Constant("") if isinstance(node.value, str) else node


def code_shape(src: str) -> str:
    """The syntax tree of a script with every string constant blanked: two exports that differ
    only in names must have the same shape (an injection adds statements or calls)."""
    return ast.dump(_Blank().visit(ast.parse(src)))


def check_python(src: str, payload: str, reference: str | None = None) -> dict:
    """The script compiles, has the shape of ``reference`` (the same export with a plain
    name), the marker is never outside a plain string literal, and the payload is one of its
    string constants; returns the module's top-level constants."""
    compile(src, "scene.py", "exec")
    if reference is not None:
        assert code_shape(src) == code_shape(reference), "the name changed the script's code"
    for tok in tokenize.generate_tokens(io.StringIO(src).readline):
        if tok.type in _CODE_TOKENS:
            assert MARK not in tok.string, f"payload outside a string literal: {tok}"
    tree = ast.parse(src)
    consts = [n.value for n in ast.walk(tree) if isinstance(n, ast.Constant)
              and isinstance(n.value, str)]
    assert any(payload in c for c in consts), "payload not kept as a string constant"
    return {t.id: n.value.value for n in tree.body if isinstance(n, ast.Assign)
            for t in n.targets if isinstance(t, ast.Name) and isinstance(n.value, ast.Constant)}


def parse_xml(text: str):
    """(root, comments) of an XML document, comments kept."""
    parser = ET.XMLParser(target=ET.TreeBuilder(insert_comments=True))
    parser.feed(text)
    root = parser.close()
    comments = [c.text for c in root.iter() if c.tag is ET.Comment]
    # a comment before the root element is not part of the tree: find it by hand
    head = text.split("<scene", 1)[0]
    if "<!--" in head:
        comments.append(head.split("<!--", 1)[1].rsplit("-->", 1)[0])
    return root, comments


def _xml_shape(root):
    return [(e.tag, tuple(sorted(e.attrib))) for e in root.iter() if e.tag is not ET.Comment]


def strip_glsl_comments(src: str) -> str:
    out, i, n = [], 0, len(src)
    while i < n:
        if src.startswith("//", i):
            j = src.find("\n", i)
            i = n if j < 0 else j
        elif src.startswith("/*", i):
            j = src.find("*/", i + 2)
            assert j >= 0, "unterminated block comment"
            i = j + 2
        else:
            out.append(src[i])
            i += 1
    return "".join(out)


def check_glsl_text(src: str, name: str):
    """No GLSL line outside comments holds the payload; a comment holds no newline of it
    (a name in a // comment with a newline would continue as code)."""
    code = strip_glsl_comments(src)
    assert MARK not in code
    for part in name.split("\n")[1:]:
        if part.strip():
            assert part not in src, "a line of the name became its own GLSL line"


# ------------------------------------------------------------------------------------------
# Mitsuba Python script
# ------------------------------------------------------------------------------------------
@pytest.mark.parametrize("key", list(PAYLOADS))
@pytest.mark.parametrize("kind", ["builtin", "plugin"])
def test_mitsuba_python_hostile_material_name(tmp_path, key, kind):
    payload = PAYLOADS[key]
    model = _gold(payload) if kind == "builtin" else _sgd(payload)
    info = M.write_mitsuba_python(model, tmp_path / "scene.py")
    assert info["plugin"] == ("builtin" if kind == "builtin" else "brdffit")
    plain = _gold("plain") if kind == "builtin" else _sgd("plain")
    M.write_mitsuba_python(plain, tmp_path / "ref" / "scene.py")
    consts = check_python((tmp_path / "scene.py").read_text(encoding="utf-8"), payload,
                          (tmp_path / "ref" / "scene.py").read_text(encoding="utf-8"))
    assert consts["MATERIAL"] == payload


@pytest.mark.parametrize("key", list(FILE_PAYLOADS))
def test_mitsuba_python_hostile_file_name(tmp_path, key):
    stem = FILE_PAYLOADS[key]
    out = tmp_path / f"{stem}.py"
    info = M.write_mitsuba_python(_sgd("paint"), out)
    M.write_mitsuba_python(_sgd("paint"), tmp_path / "ref" / "plain.py")
    ref = (tmp_path / "ref" / "plain.py").read_text(encoding="utf-8")
    assert sorted(info["files"]) == sorted([str(out), str(out.with_name(f"{stem}.fit.npz"))])
    assert out.is_file() and out.with_name(f"{stem}.fit.npz").is_file()
    consts = check_python(out.read_text(encoding="utf-8"), f"{stem}.fit.npz", ref)
    assert consts["FIT_FILE"] == f"{stem}.fit.npz"
    check_python(out.read_text(encoding="utf-8"), f"{stem}.exr", ref)


def _mitsuba_available():
    from brdffit.evaluation.render import _mitsuba

    return _mitsuba.available()


def test_mitsuba_python_scripts_run_without_injection(tmp_path):
    """The generated scripts (hostile file names and material names, built-in and plugin
    variants) are executed in a fresh interpreter (module mode, no rendering): none creates
    the injected file, and each sees its material name and fit file exactly."""
    if not _mitsuba_available():
        pytest.skip("Mitsuba 3 with the LLVM back-end is unavailable (scripts import it)")
    jobs = []
    for i, (key, stem) in enumerate(FILE_PAYLOADS.items()):
        for kind in ("builtin", "plugin"):
            d = tmp_path / f"{kind}{i}"
            d.mkdir()
            model = _gold(PAYLOADS[key]) if kind == "builtin" else _sgd(PAYLOADS[key])
            M.write_mitsuba_python(model, d / f"{stem}.py")
            jobs.append((str(d / f"{stem}.py"), PAYLOADS[key], kind))
    runner = textwrap.dedent("""
        import json, runpy, sys
        out = []
        for script, name, kind in json.load(sys.stdin):
            ns = runpy.run_path(script, run_name="brdffit_export_check")
            ok = ns["MATERIAL"] == name and ns["BSDF"]["type"] == (
                "brdffit" if kind == "plugin" else ns["BSDF"]["type"])
            out.append([script, ok, sorted(ns["scene_dict"](8, 1))])
        print(json.dumps(out))
    """)
    env = dict(os.environ, DRJIT_LIBLLVM_PATH=M.LLVM_PATH, PYTHONDONTWRITEBYTECODE="1")
    r = subprocess.run([sys.executable, "-c", runner], input=json.dumps(jobs), text=True,
                       capture_output=True, cwd=tmp_path, env=env, timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    res = json.loads(r.stdout.strip().splitlines()[-1])
    assert len(res) == len(jobs) and all(ok for _, ok, _ in res), res
    assert all("object" in keys for _, _, keys in res)
    assert not list(tmp_path.rglob("INJECTED")) and not Path("INJECTED").exists()


def test_issue_command_line_injection(tmp_path, monkeypatch, capsys):
    """The reproduction of the issue: the output name of ``export --to mitsuba``."""
    monkeypatch.chdir(tmp_path)
    name = 'x");open("INJECTED","w").write("pwned");(".py'
    assert main(["export", "synthetic:gold-ggx", "--to", "mitsuba", "-o", name]) == 0
    assert main(["export", "synthetic:gold-ggx", "--to", "mitsuba", "-o", "plain.py"]) == 0
    src = (tmp_path / name).read_text(encoding="utf-8")
    assert code_shape(src) == code_shape((tmp_path / "plain.py").read_text(encoding="utf-8"))
    calls = [n.func.id for n in ast.walk(ast.parse(src))
             if isinstance(n, ast.Call) and isinstance(n.func, ast.Name)]
    assert "open" not in calls
    capsys.readouterr()


# ------------------------------------------------------------------------------------------
# Mitsuba XML
# ------------------------------------------------------------------------------------------
@pytest.mark.parametrize("key", list(PAYLOADS))
def test_mitsuba_xml_hostile_material_name(tmp_path, key):
    payload = PAYLOADS[key]
    M.write_mitsuba_xml(_gold("plain"), tmp_path / "ref.xml")
    M.write_mitsuba_xml(_gold(payload), tmp_path / "x.xml")
    text = (tmp_path / "x.xml").read_bytes().decode("utf-8")  # the declared encoding
    root, comments = parse_xml(text)
    ref_root, _ = parse_xml((tmp_path / "ref.xml").read_bytes().decode("utf-8"))
    # same elements and attributes as with a plain name: nothing injected
    assert _xml_shape(root) == _xml_shape(ref_root)
    assert root.tag == "scene"
    for e in root.iter():
        assert all(MARK not in v for v in e.attrib.values())
    assert len(comments) == 1 and MARK in comments[0]
    assert "--" not in comments[0] and not comments[0].endswith("-")


@pytest.mark.parametrize("key", [k for k in PAYLOADS if k != "nul"])
def test_xml_string_properties_round_trip(key):
    """A string property (e.g. a bitmap file name) round-trips exactly through the XML."""
    payload = PAYLOADS[key]
    text = M.to_xml({"type": "bitmap", "filename": payload, "raw": True}, name=payload)
    el = ET.fromstring(text)
    assert el.attrib["name"] == payload and el.attrib["type"] == "bitmap"
    (prop,) = [e for e in el if e.tag == "string"]
    assert prop.attrib == {"name": "filename", "value": payload}


def test_xml_rejects_characters_xml_cannot_hold():
    with pytest.raises(ExportError, match="XML"):
        M.to_xml({"type": "bitmap", "filename": PAYLOADS["nul"]})
    with pytest.raises(ExportError, match="XML"):
        M.to_xml({"type": "bitmap", "filename": "a\x1bb"})


# ------------------------------------------------------------------------------------------
# glTF, JSON, GLSL, RGL, MERL, NPF uber-texture
# ------------------------------------------------------------------------------------------
@pytest.mark.parametrize("key", list(PAYLOADS))
def test_gltf_hostile_material_name(tmp_path, key):
    payload = PAYLOADS[key]
    export(_gold(payload), "gltf", tmp_path / "m.gltf", fidelity=False)
    doc = json.loads((tmp_path / "m.gltf").read_text(encoding="utf-8"))
    assert doc["materials"][0]["name"] == payload
    assert MARK not in "".join(k for k in _keys(doc))


def _keys(obj):
    if isinstance(obj, dict):
        for k, v in obj.items():
            yield k
            yield from _keys(v)
    elif isinstance(obj, list):
        for v in obj:
            yield from _keys(v)


@pytest.mark.parametrize("key", list(PAYLOADS))
def test_json_hostile_name_and_source_round_trip(tmp_path, key):
    payload = PAYLOADS[key]
    export(_gold(payload), "json", tmp_path / "m.json")
    doc = json.loads((tmp_path / "m.json").read_text(encoding="utf-8"))
    assert doc["name"] == payload and doc["source"] == payload
    assert MARK not in "".join(_keys(doc))
    back = brdffit.export.load_json(tmp_path / "m.json")
    assert back.name == payload


@pytest.mark.parametrize("key", list(PAYLOADS))
def test_glsl_hostile_name(tmp_path, key):
    payload = PAYLOADS[key]
    model = _sgd(payload)
    info = export(model, "glsl", tmp_path / "m.glsl")
    src = (tmp_path / "m.glsl").read_text(encoding="utf-8")
    check_glsl_text(src, payload)
    index = json.loads((tmp_path / "m.glsl.json").read_text(encoding="utf-8"))
    assert repr(payload) in index["model"]
    assert len(info["files"]) == 2


@pytest.mark.parametrize("key", list(FILE_PAYLOADS))
def test_glsl_hostile_file_name(tmp_path, key):
    stem = FILE_PAYLOADS[key]
    tab = _tabulated()
    info = export(tab, "glsl", tmp_path / f"{stem}.glsl")
    assert str(tmp_path / f"{stem}.glsl") in info["files"]
    src = (tmp_path / f"{stem}.glsl").read_text(encoding="utf-8")
    check_glsl_text(src, stem)
    index = json.loads((tmp_path / f"{stem}.glsl.json").read_text(encoding="utf-8"))
    assert len(index["textures"]) == 2
    for entry in index["textures"].values():
        assert (tmp_path / entry["file"]).is_file() and entry["file"].startswith(stem)


def _tabulated(name="tab"):
    """A small tabulated-NDF model (GLSL textures: the NDF table and the Fresnel table)."""
    from brdffit.microfacet import MicrofacetBRDF
    from brdffit.microfacet.fresnel import TabulatedFresnel
    from brdffit.microfacet.tabulated import TabulatedSlopeDistribution

    x = np.linspace(0.0, 1.0, 32)
    t = np.linspace(0.0, np.pi / 2, 90)
    fres = TabulatedFresnel(t, np.stack([0.9 - 0.1 * np.cos(t)] * 3, -1))
    return MicrofacetBRDF(TabulatedSlopeDistribution(np.exp(-30.0 * x**2)), fres, name=name)


@pytest.mark.skipif(not GL.glslang_available(), reason="glslangValidator not installed")
def test_glsl_with_hostile_names_compiles(tmp_path):
    for key, payload in PAYLOADS.items():
        export(_sgd(payload), "glsl", tmp_path / f"{key}.glsl")
        src = (tmp_path / f"{key}.glsl").read_text(encoding="utf-8")
        shader = ("#version 450\n" + src + "layout(location = 0) in vec3 v_wi;\n"
                  "layout(location = 1) in vec3 v_wo;\nlayout(location = 0) out vec4 frag;\n"
                  "void main() { frag = vec4(brdffit_eval(v_wi, v_wo), 1.0); }\n")
        ok, log = GL.compile_glsl(shader)
        assert ok, (key, log[-2000:])


@pytest.mark.parametrize("key", ["python-quotes", "newline", "non-ascii", "nul", "backslash"])
def test_rgl_description_keeps_name_escaped(tmp_path, key):
    from brdffit.io.tensorfile import read_tensor_file

    payload = PAYLOADS[key]
    export(_gold(payload), "rgl", tmp_path / "m.bsdf", check=False, n_theta=4, n_ndf=32,
           vndf_res=16, rgb_res=8)
    fields = read_tensor_file(tmp_path / "m.bsdf")
    desc = fields["description"]
    desc = desc if isinstance(desc, str) else bytes(np.asarray(desc, np.uint8)).decode("utf-8")
    assert desc.isprintable() and MARK in desc


@pytest.mark.parametrize("key", ["python-quotes", "non-ascii"])
def test_merl_hostile_file_name(tmp_path, key):
    from brdffit.io.merl import read_merl

    out = tmp_path / f"{FILE_PAYLOADS[key]}.binary"
    export(_gold(PAYLOADS[key]), "merl", out)
    assert read_merl(out).n_samples > 0
    assert sorted(p.name for p in tmp_path.iterdir()) == [out.name]


@pytest.mark.parametrize("key", list(PAYLOADS))
def test_npf_uber_hostile_names(tmp_path, key):
    from brdffit.export.tables import load_npf_table

    payload = PAYLOADS[key]
    stem = FILE_PAYLOADS[key]
    models = [_npf(0, payload), _npf(1, payload + "2")]
    GL.pack_npf_uber_texture(models, tmp_path / f"{stem}.npy", exr=False)
    index = json.loads((tmp_path / f"{stem}.json").read_text(encoding="utf-8"))
    assert index["rows"] == [payload, payload + "2"] and index["npy"] == f"{stem}.npy"
    assert list(load_npf_table(tmp_path / f"{stem}.npy")) == [payload, payload + "2"]


# ------------------------------------------------------------------------------------------
# names read from a fit file header, through the command line
# ------------------------------------------------------------------------------------------
@pytest.mark.parametrize("key", ["python-quotes", "newline", "comments", "non-ascii"])
def test_cli_export_of_fit_file_with_hostile_header(tmp_path, key, capsys):
    from brdffit.io.fitfile import save_fit

    payload = PAYLOADS[key]
    fit = save_fit(_sgd(payload), tmp_path / "in.npz", source=payload)
    for to, out in (("mitsuba", "s.py"), ("mitsuba-xml", "s.xml"), ("glsl", "s.glsl"),
                    ("json", "s.json")):
        rc = main(["export", str(fit), "--to", to, "-o", str(tmp_path / out)])
        err = capsys.readouterr().err
        assert rc == 0, err
        if to == "mitsuba-xml":          # SGD: RGL tensor + measured plugin; XML well formed
            import xml.etree.ElementTree as ET

            root = ET.parse(tmp_path / out).getroot()
            fname = root.find("bsdf/string").get("value")
            assert (tmp_path / fname).is_file() and payload not in fname
    consts = check_python((tmp_path / "s.py").read_text(encoding="utf-8"), payload)
    assert consts["MATERIAL"] == payload
    check_glsl_text((tmp_path / "s.glsl").read_text(encoding="utf-8"), payload)
    doc = json.loads((tmp_path / "s.json").read_text(encoding="utf-8"))
    assert doc["name"] == payload and doc["source"] == payload


def test_nul_in_output_name_is_one_clean_error(tmp_path, capsys):
    """No file system allows NUL in a name: one ExportError naming the file (escaped), for every
    target, and nothing written. (A shell cannot pass NUL in argv; the command line rejects it
    as a bad ``-o`` value with status 2.)"""
    bad = tmp_path / "a\x00b.out"
    for to in ("json", "gltf", "glsl", "mitsuba", "mitsuba-xml", "merl", "rgl"):
        with pytest.raises(ExportError) as ei:
            export(_gold("x"), to, bad)
        msg = str(ei.value)
        assert "\n" not in msg and "a\\x00b.out" in msg and "NUL" in msg, msg
    with pytest.raises(ExportError, match="NUL"):
        GL.pack_npf_uber_texture([_npf(0, "a")], bad)
    rc = main(["export", "synthetic:gold-ggx", "--to", "json", "-o", str(bad)])
    assert rc == 2 and "Traceback" not in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


def test_unrepresentable_model_is_one_line(tmp_path, capsys):
    # (anisotropic models go to rgl since issue 14.4: phi_i slices)
    for to, model, out in (("materialx", "sgd-paint", "x.mtlx"), ("gltf", "sgd-paint", "x.gltf"),
                           ("merl", "aniso-ggx", "x.binary")):
        rc = main(["export", f"synthetic:{model}", "--to", to, "-o", str(tmp_path / out)])
        err = capsys.readouterr().err
        assert rc == 1 and len(err.strip().splitlines()) == 1 and err.startswith("brdffit: error:")
        assert "cannot export" in err
    assert list(tmp_path.iterdir()) == []
