"""The package as a user meets it: documented names, stubs that declare them, the README's
example running."""

import ast
import pathlib
import re

import sdem

PACKAGE = pathlib.Path(sdem.__file__).parent
ROOT = pathlib.Path(__file__).resolve().parents[3]


def test_every_public_name_has_a_docstring_and_the_stubs_declare_it():
    stubbed = set()
    for stub in ("_sdem.pyi", "sim.pyi"):
        tree = ast.parse((PACKAGE / stub).read_text())
        for node in tree.body:
            if isinstance(node, (ast.ClassDef, ast.FunctionDef)):
                stubbed.add(node.name)
            elif isinstance(node, ast.AnnAssign):
                stubbed.add(node.target.id)
    assert (PACKAGE / "py.typed").exists()
    for name in sdem.__all__:
        obj = getattr(sdem, name)
        if name.endswith("Error"):
            continue  # defined in Python, in sdem/_errors.py (its own types)
        if callable(obj) or isinstance(obj, type(sdem)):
            assert obj.__doc__ and len(obj.__doc__) > 40, name
        assert name in stubbed or name == "__version__", name
    for cls in (sdem.Scan, sdem.Localization, sdem.Slam, sdem.Step, sdem.Map,
                sdem.Relocalization, sdem.Doubt):
        for attr, value in vars(cls).items():
            if not attr.startswith("_"):
                assert value.__doc__, f"{cls.__name__}.{attr}"
    for fn in (sdem.sim.pairs, sdem.sim.run):
        assert fn.__doc__ and "seed" in fn.__doc__


def test_help_on_localize_reads_like_the_rust_docs_and_names_every_option():
    doc = sdem.localize.__doc__
    assert doc.startswith("Localizes ``query`` against ``reference``")
    for section in ("Args:", "Returns:", "Raises:"):
        assert section in doc
    for option in sdem.localize_options():
        assert f"``{option}``" in doc, option
    for option in sdem.slam_options():
        assert f"``{option}``" in sdem.Slam.__doc__, option


def test_the_readme_python_example_runs(capsys):
    readme = (ROOT / "README.md").read_text()
    section = readme[readme.index("## Python"):]
    code = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    exec(compile(code, "README.md", "exec"), {})
    printed = capsys.readouterr().out
    assert "True" in printed
