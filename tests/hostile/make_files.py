"""Write the hostile scenario files of this folder (they are committed; run this after changing one).

python tests/hostile/make_files.py
"""

from pathlib import Path

HERE = Path(__file__).parent

BASE = """name: hostile
seed: 1
protocol: {kind: learn, trials: 5}
space:
  - {name: x, target: body.x, low: 0, high: 1}
  - {name: y, target: body.y, low: 0, high: 1}
modules:
  acc: {impl: acc}
  vigilance: {impl: vigilance, params: {mode: fixed, value: -0.1}}
  ofc: {impl: ofc}
  body: {impl: analytic}
"""

WALKER = """name: hostile_walker
seed: 1
protocol: {kind: sweep}
space:
  - {name: alpha_hip, target: controller.alpha_hip, low: 0.0, high: 20.0, steps: 2}
conditions:
  body.terrain: "0.5:0,1.0:6"
modules:
  controller: {impl: reflex}
  body: {impl: planar_biped}
"""


def sub(text, old, new):
    assert old in text, old
    return text.replace(old, new, 1)


files: dict[str, str | bytes] = {}

# --- YAML bombs and limits -------------------------------------------------------------------
lol = ['a: &a ["lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol"]']
for prev, cur in zip("abcdefgh", "bcdefghi", strict=True):
    lol.append(f"{cur}: &{cur} [" + ", ".join([f"*{prev}"] * 9) + "]")
files["alias_bomb.yaml"] = BASE + "description: x\n" + "bomb:\n" + "".join(f"  {line}\n" for line in lol)
files["alias_recursive.yaml"] = BASE + "loop: &loop [1, *loop]\n"
chain = ["c0: &c0 [1]"] + [f"c{i}: &c{i} [*c{i - 1}]" for i in range(1, 40)]
files["alias_deep_chain.yaml"] = BASE + "chain:\n" + "".join(f"  {line}\n" for line in chain)
files["deep_nesting_lists.yaml"] = BASE + "description: " + "[" * 5000 + "]" * 5000 + "\n"
files["deep_nesting_mappings.yaml"] = BASE + "extra: " + "{a: " * 2000 + "1" + "}" * 2000 + "\n"
files["deep_nesting_block.yaml"] = (
    BASE + "extra:\n" + "".join("  " * (i + 1) + f"k{i}:\n" for i in range(60)) + "  " * 61 + "v: 1\n"
)
files["many_values.yaml"] = BASE + "extra: [" + ", ".join(["1"] * 30000) + "]\n"
files["huge_int.yaml"] = sub(BASE, "seed: 1", "seed: " + "9" * 5000)
files["huge_float.yaml"] = sub(BASE, "low: 0, high: 1}\n  - {name: y", "low: 1.0e+999, high: 1}\n  - {name: y")

# --- encodings and bytes ---------------------------------------------------------------------
files["non_utf8.yaml"] = sub(BASE, "seed: 1\n", "seed: 1\ndescription: caf\udce9 au lait\n").encode(
    "utf-8", "surrogateescape"
)
files["utf16.yaml"] = BASE.encode("utf-16")
files["binary_garbage.yaml"] = bytes((i * 73 + 41) % 256 for i in range(4096))
files["nul_byte.yaml"] = sub(BASE, "name: hostile", "name: host\x00ile").encode()
files["control_chars.yaml"] = sub(BASE, "seed: 1\n", "seed: 1\ndescription: \x1b[31mred\n").encode()

# --- YAML structure --------------------------------------------------------------------------
files["empty.yaml"] = ""
files["comments_only.yaml"] = "# nothing here\n# at all\n"
files["top_list.yaml"] = "- name: hostile\n- seed: 1\n"
files["top_scalar.yaml"] = "hello\n"
files["two_documents.yaml"] = BASE + "---\nname: second\n"
files["yaml_syntax.yaml"] = BASE + "description: [unclosed\n"
files["tab_indent.yaml"] = sub(BASE, "  acc: {impl: acc}", "\tacc: {impl: acc}")
files["duplicate_top.yaml"] = sub(BASE, "modules:", "seed: 2\nmodules:")
files["duplicate_nested.yaml"] = sub(BASE, "{kind: learn, trials: 5}", "{kind: learn, trials: 5, trials: 500}")
files["duplicate_module.yaml"] = BASE + "  acc: {impl: acc, params: {shape: [3, 3]}}\n"
files["duplicate_in_list_item.yaml"] = sub(
    BASE, "low: 0, high: 1}\n  - {name: y", "low: 0, high: 1, low: 0.5}\n  - {name: y"
)
files["bool_key.yaml"] = BASE + "on: true\n"
files["int_key.yaml"] = BASE + "  1: {impl: ofc}\n"
files["python_tag.yaml"] = sub(BASE, "name: hostile", 'name: !!python/object/apply:os.system ["echo pwned"]')
files["python_name_tag.yaml"] = sub(BASE, "seed: 1", "seed: !!python/name:os.getpid")
files["custom_tag.yaml"] = sub(BASE, "seed: 1", "seed: !env SEED")
files["set_tag.yaml"] = BASE + "extra: !!set {a, b}\n"
files["binary_tag.yaml"] = sub(BASE, "seed: 1\n", "seed: 1\ndescription: !!binary aGVsbG8=\n")
files["bad_explicit_int.yaml"] = sub(BASE, "seed: 1", "seed: !!int abc")
files["merge_not_mapping.yaml"] = sub(
    BASE, "protocol: {kind: learn, trials: 5}", "protocol: {<<: 3, kind: learn, trials: 5}"
)

# --- strict types ------------------------------------------------------------------------------
files["trials_string.yaml"] = sub(BASE, "trials: 5", 'trials: "40"')
files["trials_bool.yaml"] = sub(BASE, "trials: 5", "trials: true")
files["trials_float.yaml"] = sub(BASE, "trials: 5", "trials: 40.0")
files["seed_string.yaml"] = sub(BASE, "seed: 1", 'seed: "7"')
files["seed_float.yaml"] = sub(BASE, "seed: 1", "seed: 7.5")
files["low_string.yaml"] = sub(BASE, "low: 0, high: 1}\n  - {name: y", "low: '0', high: 1}\n  - {name: y")
files["high_yes.yaml"] = sub(BASE, "low: 0, high: 1}\n  - {name: y", "low: 0, high: yes}\n  - {name: y")
files["shape_strings.yaml"] = sub(BASE, "acc: {impl: acc}", 'acc: {impl: acc, params: {shape: ["10", 10]}}')
files["param_bool_for_number.yaml"] = sub(BASE, "value: -0.1", "value: false")
files["modules_list.yaml"] = BASE.split("modules:")[0] + "modules: [acc, vigilance, ofc, body]\n"
files["params_null.yaml"] = sub(BASE, "acc: {impl: acc}", "acc: {impl: acc, params: }")

# --- finite numbers ----------------------------------------------------------------------------
files["low_inf.yaml"] = sub(BASE, "low: 0, high: 1}\n  - {name: y", "low: -.inf, high: 1}\n  - {name: y")
files["high_nan.yaml"] = sub(BASE, "low: 0, high: 1}\n  - {name: y", "low: 0, high: .nan}\n  - {name: y")
files["condition_inf.yaml"] = sub(BASE, "modules:", "conditions:\n  body.z: .inf\nmodules:")
files["param_nan.yaml"] = sub(BASE, "value: -0.1", "value: .NaN")
files["timeout_inf.yaml"] = BASE + "timeouts: {ready: .inf}\n"
files["lease_too_short.yaml"] = BASE + "timeouts: {lease: 0.1}\n"
files["timeout_misspelt.yaml"] = BASE + "timeouts: {hang: 60}\n"

# --- what would fail at start --------------------------------------------------------------------
files["map_shape_huge.yaml"] = sub(BASE, "acc: {impl: acc}", "acc: {impl: acc, params: {shape: [1000, 1000, 1000]}}")
files["map_shape_just_too_big.yaml"] = sub(BASE, "acc: {impl: acc}", "acc: {impl: acc, params: {shape: [65, 64]}}")
files["terrain_unknown.yaml"] = sub(WALKER, '"0.5:0,1.0:6"', "hilly")
files["terrain_malformed.yaml"] = sub(WALKER, '"0.5:0,1.0:6"', '"0.5:0,1.0:"')
files["terrain_steep.yaml"] = sub(WALKER, '"0.5:0,1.0:6"', '"0.5:0,1.0:80"')
files["terrain_number.yaml"] = sub(WALKER, '"0.5:0,1.0:6"', "3")
files["terrain_axis.yaml"] = sub(WALKER, "target: controller.alpha_hip", "target: body.terrain")
files["slope_text.yaml"] = sub(WALKER, 'body.terrain: "0.5:0,1.0:6"', "body.slope_deg: steep")
files["impl_raises.yaml"] = sub(BASE, "impl: vigilance,", "impl: raises_on_import.py:Vigilance,")
files["impl_exits.yaml"] = sub(BASE, "impl: vigilance,", "impl: exits_on_import.py:Vigilance,")
files["impl_base_exception.yaml"] = sub(BASE, "impl: vigilance,", "impl: base_exception_on_import.py:Vigilance,")
files["impl_hangs.yaml"] = (
    sub(BASE, "impl: vigilance,", "impl: hangs_on_import.py:Vigilance,") + "timeouts: {ready: 0.5}\n"
)
files["impl_missing_file.yaml"] = sub(BASE, "impl: vigilance,", "impl: nowhere.py:Vigilance,")
files["impl_missing_module.yaml"] = sub(BASE, "impl: vigilance,", "impl: no_such_package.vig:Vigilance,")
files["impl_not_a_module.yaml"] = sub(BASE, "impl: vigilance,", "impl: json:JSONDecoder,")
files["impl_unregistered.yaml"] = sub(BASE, "impl: vigilance,", "impl: vigilence,")
files["restart_brain.yaml"] = sub(BASE, "acc: {impl: acc}", "acc: {impl: acc, restart: on-failure}")
files["restart_typo.yaml"] = sub(BASE, "body: {impl: analytic}", "body: {impl: analytic, restart: on-failur}")

# --- unknown keys and names ------------------------------------------------------------------
files["unknown_key.yaml"] = sub(BASE, "protocol:", "protocl:")
files["unknown_nested_key.yaml"] = sub(BASE, "low: 0, high: 1}\n  - {name: y", "low: 0, hihg: 1}\n  - {name: y")
files["unknown_param.yaml"] = sub(BASE, "value: -0.1", "value: -0.1, stepp: 0.1")
files["enum_typo.yaml"] = BASE + "lockstep: {pin_cpus: alwys}\n"
files["protocol_typo.yaml"] = sub(BASE, "kind: learn", "kind: lern")

for name, content in files.items():
    path = HERE / name
    if isinstance(content, bytes):
        path.write_bytes(content)
    else:
        path.write_text(content)
print(len(files))
