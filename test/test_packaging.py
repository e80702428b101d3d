"""Packaging: package.xml, setup.py/setup.cfg, default-config lookup, and the two
ways in: the plain venv (pip) and a colcon-built ROS 2 workspace."""

from __future__ import annotations

import configparser
import importlib.metadata
import importlib.util
import os
import shutil
import subprocess
import sys
import textwrap
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

import jident_ros
from jident_ros import resources

VENV_BIN = Path(sys.executable).parent
SETUP_HINT = "run `bash scripts/setup.sh` (builds .venv with the package installed -e, colcon and the ros-* wheels)"
PACKAGE_NAME = "jident_ros"
# What a ROS workspace needs of this repository (copied into <ws>/src/jident_ros).
PACKAGE_ITEMS = ("package.xml", "setup.py", "setup.cfg", "resource", "config", "jident_ros", "launch")
REQUIRED_EXEC_DEPENDS = {
    "rclpy",
    "std_msgs",
    "diagnostic_msgs",
    "rosgraph_msgs",
    "python3-numpy",
    "python3-scipy",
    "python3-pywt",
    "python3-yaml",
    "python3-matplotlib",
}


def _run(cmd, *, env=None, cwd=None, timeout=300):
    result = subprocess.run(
        [str(c) for c in cmd], env=env, cwd=cwd, capture_output=True, text=True, timeout=timeout
    )
    return result


def _explain(result) -> str:
    return (
        f"command {result.args} exited {result.returncode}\n"
        f"--- stdout (tail) ---\n{result.stdout[-4000:]}\n--- stderr (tail) ---\n{result.stderr[-4000:]}"
    )


def _copy_package(repo_root: Path, dest: Path) -> Path:
    dest.mkdir(parents=True)
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc", "*.egg-info")
    for item in PACKAGE_ITEMS:
        src = repo_root / item
        if src.is_dir():
            shutil.copytree(src, dest / item, ignore=ignore)
        elif src.is_file():
            shutil.copy2(src, dest / item)
    return dest


# --------------------------------------------------------------------------- package.xml


def test_package_xml_is_format3_ament_python(repo_root):
    root = ET.parse(repo_root / "package.xml").getroot()
    assert root.tag == "package"
    assert root.get("format") == "3"
    assert root.findtext("name") == PACKAGE_NAME
    assert root.findtext("version") == "0.1.0"
    assert root.findtext("license") == "Apache-2.0"
    maintainer = root.find("maintainer")
    assert maintainer is not None and maintainer.text == "jident developers" and maintainer.get("email")
    exec_depends = {e.text.strip() for e in root.findall("exec_depend")}
    assert REQUIRED_EXEC_DEPENDS <= exec_depends, f"missing exec_depend: {REQUIRED_EXEC_DEPENDS - exec_depends}"
    assert [e.text for e in root.findall("test_depend")] == ["python3-pytest"]
    assert root.findtext("export/build_type") == "ament_python"


def test_package_xml_valid_for_ros_tools(repo_root):
    """catkin_pkg is the parser colcon-ros, rosdep and bloom use."""
    if importlib.util.find_spec("catkin_pkg") is None:
        pytest.fail(f"catkin_pkg (from colcon-ros) is not installed in {sys.prefix}: {SETUP_HINT}")
    from catkin_pkg.package import parse_package

    pkg = parse_package(str(repo_root / "package.xml"))
    pkg.validate()
    assert pkg.package_format == 3
    assert pkg.get_build_type() == "ament_python"
    assert {d.name for d in pkg.exec_depends} >= REQUIRED_EXEC_DEPENDS


def _rosdep_keys(repo_root):
    """(package.xml's dependency keys, the rosdistro keys kept in test data, our own rosdep YAML's keys)."""
    import yaml

    root = ET.parse(repo_root / "package.xml").getroot()
    deps = {e.text.strip() for e in root if e.tag.endswith("depend") and e.text}
    kept = yaml.safe_load((repo_root / "test" / "data" / "rosdistro_keys.yaml").read_text())
    ours = yaml.safe_load((repo_root / "rosdep" / "jident_ros.yaml").read_text())
    return deps, kept, ours


def test_every_package_xml_key_resolves_with_rosdep(repo_root):
    """Each dependency key is a rosdistro key (rosdep YAML or a released Jazzy package, kept in
    test/data/rosdistro_keys.yaml with its commit and date) or one of our rosdep/jident_ros.yaml --
    never both, and never a key rosdistro does not have (python3-pywavelets was one)."""
    deps, kept, ours = _rosdep_keys(repo_root)
    assert kept["commit"] and kept["date"]
    known = set(kept["rosdep_keys"]) | set(kept["jazzy_packages"])
    unresolved = deps - known - set(ours)
    assert not unresolved, f"package.xml keys with no rosdep definition: {sorted(unresolved)}"
    assert not set(ours) & known, "our rosdep YAML redefines a rosdistro key"
    assert set(ours) <= set(kept["keys_not_in_rosdistro"]), "an own key not checked as absent from rosdistro"
    assert "python3-pywavelets" not in deps


def test_own_rosdep_keys_install_on_ubuntu_and_debian(repo_root):
    deps, _, ours = _rosdep_keys(repo_root)
    assert set(ours) <= deps, f"own rosdep keys nobody depends on: {sorted(set(ours) - deps)}"
    for key, rule in ours.items():
        for os_name in ("ubuntu", "debian"):
            how = rule.get(os_name)
            assert how, f"{key}: no rule for {os_name}"
            assert isinstance(how, list) or how.get("pip", {}).get("packages"), f"{key}/{os_name}: {how}"


def test_every_imported_third_party_module_is_declared(repo_root):
    """The runtime's third-party imports each have a key in package.xml (no rosbags.typesys surprise)."""
    deps, _, _ = _rosdep_keys(repo_root)
    key_of = {"numpy": "python3-numpy", "scipy": "python3-scipy", "yaml": "python3-yaml",
              "matplotlib": "python3-matplotlib", "tqdm": "python3-tqdm", "rosbags": "python3-rosbags-pip",
              "pywt": "python3-pywt", "mcap": "python3-mcap-pip", "zstandard": "python3-zstandard",
              "lz4": "python3-lz4"}
    import ast

    imported = set()
    for path in (repo_root / "jident_ros").rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                imported |= {a.name.split(".")[0] for a in node.names}
            elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
                imported.add(node.module.split(".")[0])
    for module, key in key_of.items():
        if module in imported or module in ("zstandard", "lz4"):  # mcap's chunk compressions (zstd, lz4)
            assert key in deps, f"{module} is imported but {key} is not in package.xml"
    ros_modules = {m for m in imported if m.endswith("_msgs") or m in ("rclpy", "launch", "launch_ros",
                                                                      "ament_index_python", "rcl_interfaces")}
    assert ros_modules <= deps, f"ROS packages imported but not declared: {sorted(ros_modules - deps)}"


def test_versions_agree(repo_root):
    xml_version = ET.parse(repo_root / "package.xml").getroot().findtext("version")
    assert jident_ros.__version__ == xml_version
    try:
        dist_version = importlib.metadata.version(PACKAGE_NAME)
    except importlib.metadata.PackageNotFoundError:
        pytest.fail(f"{PACKAGE_NAME} is not pip-installed in {sys.prefix}: {SETUP_HINT}")
    assert dist_version == xml_version, "setup.py version differs from package.xml"


def test_install_requires_never_pull_ros_wheels():
    """A ROS distribution's own rclpy must never be replaced by pip."""
    try:
        requires = importlib.metadata.requires(PACKAGE_NAME) or []
    except importlib.metadata.PackageNotFoundError:
        pytest.fail(f"{PACKAGE_NAME} is not pip-installed in {sys.prefix}: {SETUP_HINT}")
    core = [r for r in requires if "extra ==" not in r]
    names = {r.split(";")[0].split("[")[0].split("<")[0].split(">")[0].split("=")[0].strip().lower() for r in core}
    assert names == {"numpy", "scipy", "pywavelets", "pyyaml", "matplotlib", "tqdm", "rosbags", "mcap", "zstandard", "lz4"}
    assert not [r for r in requires if r.lower().startswith(("ros-", "rclpy"))]


# --------------------------------------------------------------------------- setup.cfg / layout


def test_setup_cfg_installs_executables_where_ros2_run_looks(repo_root):
    cfg = configparser.ConfigParser(interpolation=None)
    assert cfg.read(repo_root / "setup.cfg"), "setup.cfg missing"
    assert cfg.get("develop", "script_dir") == "$base/lib/jident_ros"
    assert cfg.get("install", "install_scripts") == "$base/lib/jident_ros"


def test_ament_resource_marker(repo_root):
    marker = repo_root / "resource" / PACKAGE_NAME
    assert marker.is_file() and marker.stat().st_size == 0


def test_every_code_folder_is_a_package(repo_root):
    """find_packages() silently drops folders without __init__.py."""
    missing = [
        str(d.relative_to(repo_root))
        for d in (repo_root / PACKAGE_NAME).rglob("*")
        if d.is_dir() and d.name != "__pycache__" and any(d.glob("*.py")) and not (d / "__init__.py").is_file()
    ]
    assert not missing, f"folders with modules but no __init__.py (would not be installed): {missing}"


def test_default_config_exists(repo_root):
    assert (repo_root / "config" / "system.yaml").is_file()


# --------------------------------------------------------------------------- resources.py


@pytest.fixture
def clean_lookup(monkeypatch, tmp_path):
    """No env override, no ament prefixes, and sys.prefix / user base in empty tmp dirs."""
    monkeypatch.delenv(resources.CONFIG_ENV_VAR, raising=False)
    monkeypatch.delenv("AMENT_PREFIX_PATH", raising=False)
    monkeypatch.setattr(sys, "prefix", str(tmp_path / "empty_prefix"))
    monkeypatch.setattr(resources.site, "getuserbase", lambda: str(tmp_path / "empty_userbase"))
    return monkeypatch


def _config_dir_under(prefix: Path) -> Path:
    d = prefix / "share" / PACKAGE_NAME / "config"
    d.mkdir(parents=True, exist_ok=True)
    return d


def _fake_ament_prefix(prefix: Path) -> Path:
    marker = prefix / "share" / "ament_index" / "resource_index" / "packages" / PACKAGE_NAME
    marker.parent.mkdir(parents=True, exist_ok=True)
    marker.touch()
    return _config_dir_under(prefix)


def test_config_found_in_checkout(repo_root, clean_lookup):
    assert resources.default_config_path("system.yaml") == repo_root / "config" / "system.yaml"
    assert resources.default_config_path() == repo_root / "config" / "system.yaml"


def test_config_env_var_wins(repo_root, clean_lookup, tmp_path):
    env_dir = tmp_path / "cfg"
    env_dir.mkdir()
    (env_dir / "system.yaml").write_text("j1: 2.0\n")
    (env_dir / "only_here.yaml").write_text("x: 1\n")
    clean_lookup.setenv(resources.CONFIG_ENV_VAR, str(env_dir))
    assert resources.default_config_path("system.yaml") == env_dir / "system.yaml"
    assert resources.default_config_path("only_here.yaml") == env_dir / "only_here.yaml"


def test_config_env_var_without_file_falls_through(repo_root, clean_lookup, tmp_path):
    clean_lookup.setenv(resources.CONFIG_ENV_VAR, str(tmp_path))
    assert resources.default_config_path("system.yaml") == repo_root / "config" / "system.yaml"


def test_config_found_via_ament_index(clean_lookup, tmp_path):
    pytest.importorskip("ament_index_python", reason="ament_index_python not installed")
    ament_cfg = _fake_ament_prefix(tmp_path / "ament_prefix")
    (ament_cfg / "only_in_ament.yaml").write_text("x: 1\n")
    # also present under sys.prefix: the ament index comes first
    prefix_cfg = _config_dir_under(Path(sys.prefix))
    (prefix_cfg / "only_in_ament.yaml").write_text("x: 2\n")
    clean_lookup.setenv("AMENT_PREFIX_PATH", str(tmp_path / "ament_prefix"))
    assert resources.default_config_path("only_in_ament.yaml") == ament_cfg / "only_in_ament.yaml"


def test_config_found_under_sys_prefix(clean_lookup, tmp_path):
    prefix = tmp_path / "venv"
    clean_lookup.setattr(sys, "prefix", str(prefix))
    cfg = _config_dir_under(prefix)
    (cfg / "only_in_prefix.yaml").write_text("x: 1\n")
    assert resources.default_config_path("only_in_prefix.yaml") == cfg / "only_in_prefix.yaml"


def test_config_found_under_user_base(clean_lookup, tmp_path):
    user_base = tmp_path / "userbase"
    clean_lookup.setattr(resources.site, "getuserbase", lambda: str(user_base))
    cfg = _config_dir_under(user_base)
    (cfg / "only_in_user.yaml").write_text("x: 1\n")
    assert resources.default_config_path("only_in_user.yaml") == cfg / "only_in_user.yaml"


def test_config_without_ament_index_python(clean_lookup, tmp_path):
    clean_lookup.setitem(sys.modules, "ament_index_python", None)
    clean_lookup.setitem(sys.modules, "ament_index_python.packages", None)
    labels = [label for label, _ in resources.config_search_dirs()]
    assert any("not importable" in label for label in labels)
    cfg = _config_dir_under(Path(sys.prefix))
    (cfg / "x.yaml").write_text("x: 1\n")
    assert resources.default_config_path("x.yaml") == cfg / "x.yaml"


def test_checkout_branch_needs_package_xml(clean_lookup, tmp_path):
    """An installed copy in site-packages must not pick up some stray site-packages/config."""
    site_packages = tmp_path / "site-packages"
    (site_packages / "config").mkdir(parents=True)
    (site_packages / "config" / "stray.yaml").write_text("x: 1\n")
    clean_lookup.setattr(resources, "__file__", str(site_packages / PACKAGE_NAME / "resources.py"))
    with pytest.raises(FileNotFoundError):
        resources.default_config_path("stray.yaml")


def test_config_missing_names_every_place(repo_root, clean_lookup, tmp_path):
    clean_lookup.setenv(resources.CONFIG_ENV_VAR, str(tmp_path / "envcfg"))
    with pytest.raises(FileNotFoundError) as info:
        resources.default_config_path("no_such_config.yaml")
    message = str(info.value)
    for expected in (
        "no_such_config.yaml",
        str(tmp_path / "envcfg" / "no_such_config.yaml"),
        str(repo_root / "config" / "no_such_config.yaml"),
        "ament index",
        str(tmp_path / "empty_prefix" / "share" / PACKAGE_NAME / "config" / "no_such_config.yaml"),
        str(tmp_path / "empty_userbase" / "share" / PACKAGE_NAME / "config" / "no_such_config.yaml"),
        resources.CONFIG_ENV_VAR,
    ):
        assert expected in message, f"{expected!r} not named in:\n{message}"


def test_config_name_must_be_relative(clean_lookup):
    with pytest.raises(ValueError):
        resources.default_config_path("/etc/passwd")


# --------------------------------------------------------------------------- way in 1: plain venv


def test_venv_console_script(repo_root):
    exe = VENV_BIN / "jident"
    if not exe.is_file():
        pytest.fail(f"{exe} is missing: {SETUP_HINT}")
    result = _run([exe, "--help"], timeout=120)
    assert result.returncode == 0, _explain(result)
    assert "usage" in result.stdout.lower()
    where = _run([sys.executable, "-c", "import jident_ros; print(jident_ros.__file__)"], cwd="/")
    assert Path(where.stdout.strip()).resolve() == (repo_root / PACKAGE_NAME / "__init__.py").resolve(), (
        f"the venv's jident_ros is not the editable checkout: {where.stdout} {where.stderr}"
    )


def test_pip_wheel_install_ships_config(repo_root, tmp_path):
    """Non-editable `pip install .`: config lands in <prefix>/share/jident_ros/config and is found there."""
    if importlib.util.find_spec("wheel") is None:
        pytest.fail(f"the `wheel` package is missing from {sys.prefix}: {SETUP_HINT}")
    src = _copy_package(repo_root, tmp_path / "src")
    dist = tmp_path / "dist"
    built = _run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "--no-index", "-w", dist, src],
        timeout=300,
    )
    assert built.returncode == 0, _explain(built)
    (wheel,) = dist.glob("jident_ros-*.whl")

    target = tmp_path / "target_venv"
    made = _run([sys.executable, "-m", "venv", "--without-pip", target])
    assert made.returncode == 0, _explain(made)
    target_py = target / "bin" / "python"
    inst = _run([sys.executable, "-m", "pip", "--python", target_py, "install", "--no-deps", "--no-index", wheel])
    assert inst.returncode == 0, _explain(inst)

    assert (target / "share" / PACKAGE_NAME / "config" / "system.yaml").is_file()
    assert (target / "share" / PACKAGE_NAME / "config" / "profiles" / "heavy_film.yaml").is_file()
    assert (target / "share" / PACKAGE_NAME / "package.xml").is_file()
    assert (target / "share" / "ament_index" / "resource_index" / "packages" / PACKAGE_NAME).is_file()
    assert (target / "bin" / "jident").is_file(), "pip puts console scripts in bin/ (setup.cfg must not move them)"

    # Third-party deps come from this venv (appended, so the target's own jident_ros wins).
    import sysconfig

    env = {k: v for k, v in os.environ.items() if k not in ("AMENT_PREFIX_PATH", resources.CONFIG_ENV_VAR)}
    env["PYTHONPATH"] = sysconfig.get_paths()["purelib"]
    probe = textwrap.dedent(
        """
        import jident_ros, jident_ros.resources as r
        print(jident_ros.__file__)
        print(r.default_config_path('system.yaml'))
        import jident_ros.config as c
        print(c.resolve_config_path('heavy_film'))
        print(c.load_system_config('heavy_film').load.film_area_m2)
        """
    )
    found = _run([target_py, "-c", probe], env=env, cwd=tmp_path)
    assert found.returncode == 0, _explain(found)
    module_file, config_file, profile_file, film_area = found.stdout.splitlines()
    assert Path(profile_file) == target / "share" / PACKAGE_NAME / "config" / "profiles" / "heavy_film.yaml"
    assert float(film_area) == 0.14
    assert Path(module_file).is_relative_to(target), module_file
    assert Path(config_file) == target / "share" / PACKAGE_NAME / "config" / "system.yaml"
    helped = _run([target / "bin" / "jident", "--help"], env=env, cwd=tmp_path, timeout=120)
    assert helped.returncode == 0, _explain(helped)


# --------------------------------------------------------------------------- way in 2: colcon


@pytest.mark.colcon
def test_colcon_build_and_ros2_run_lookup(repo_root, tmp_path, ros_env):
    colcon = VENV_BIN / "colcon"
    if not colcon.is_file() or importlib.util.find_spec("colcon_ros") is None:
        pytest.fail(f"colcon with colcon-ros is not installed in {sys.prefix}: {SETUP_HINT}")
    ws = tmp_path / "ws"
    _copy_package(repo_root, ws / "src" / PACKAGE_NAME)
    build_env = {
        k: v
        for k, v in ros_env.items()
        if k not in ("AMENT_PREFIX_PATH", "COLCON_PREFIX_PATH", "CMAKE_PREFIX_PATH", "PYTHONPATH")
    }
    build_env["COLCON_HOME"] = str(tmp_path / "colcon_home")  # ignore the user's colcon defaults
    build_env["PATH"] = f"{VENV_BIN}{os.pathsep}{build_env.get('PATH', '')}"

    listed = _run([colcon, "--log-base", ws / "log", "list", "--base-paths", ws / "src"], env=build_env, cwd=ws)
    assert listed.returncode == 0, _explain(listed)
    assert "(ros.ament_python)" in listed.stdout, f"colcon does not see an ament_python package:\n{listed.stdout}"

    built = _run(
        [
            colcon, "--log-base", ws / "log", "build",
            "--base-paths", ws / "src",
            "--build-base", ws / "build",
            "--install-base", ws / "install",
            "--event-handlers", "console_direct-", "console_cohesion+", "desktop_notification-",
        ],
        env=build_env,
        cwd=ws,
        timeout=300,
    )
    assert built.returncode == 0, _explain(built)

    prefix = ws / "install" / PACKAGE_NAME
    exe = prefix / "lib" / PACKAGE_NAME / "jident"
    assert exe.is_file(), f"{exe} missing; install tree: {sorted(str(p) for p in prefix.rglob('*'))[:50]}"
    assert os.access(exe, os.X_OK)
    assert not (prefix / "bin" / "jident").exists()
    share = prefix / "share" / PACKAGE_NAME
    assert (share / "package.xml").is_file()
    assert (share / "config" / "system.yaml").is_file()
    assert (prefix / "share" / "ament_index" / "resource_index" / "packages" / PACKAGE_NAME).is_file()

    # Find and run it the way `ros2 run jident_ros jident` does: ament index -> <prefix>/lib/<pkg>/<exe>.
    site_packages = next((prefix / "lib").glob("python3*/site-packages"))
    run_env = dict(ros_env)
    run_env["AMENT_PREFIX_PATH"] = os.pathsep.join([str(prefix), sys.prefix])
    run_env["PYTHONPATH"] = str(site_packages)
    run_env.pop(resources.CONFIG_ENV_VAR, None)
    probe = textwrap.dedent(
        """
        import os
        from ament_index_python.packages import get_package_prefix
        import jident_ros, jident_ros.resources as r
        print(os.path.join(get_package_prefix('jident_ros'), 'lib', 'jident_ros', 'jident'))
        print(jident_ros.__file__)
        print(r.default_config_path('system.yaml'))
        import jident_ros.config as c
        print(c.resolve_config_path('heavy_film'))
        print(c.load_system_config('heavy_film').load.film_area_m2)
        """
    )
    found = _run([sys.executable, "-c", probe], env=run_env, cwd=tmp_path)
    assert found.returncode == 0, _explain(found)
    exe_found, module_file, config_file, profile_file, film_area = found.stdout.splitlines()
    assert Path(profile_file) == share / "config" / "profiles" / "heavy_film.yaml", profile_file
    assert float(film_area) == 0.14
    assert Path(exe_found) == exe
    assert Path(module_file).is_relative_to(prefix), "the installed copy must be imported, not the checkout"
    assert Path(config_file) == share / "config" / "system.yaml"
    helped = _run([exe_found, "--help"], env=run_env, cwd=tmp_path, timeout=120)
    assert helped.returncode == 0, _explain(helped)
    assert "usage" in helped.stdout.lower()

    # Same through the generated setup script, as a user would: source install/setup.bash.
    sourced_env = {k: v for k, v in ros_env.items() if k not in ("PYTHONPATH", resources.CONFIG_ENV_VAR)}
    script = (
        f'source "{ws}/install/setup.bash" && '
        f'exe="$("{sys.executable}" -c "from ament_index_python.packages import get_package_prefix as g; '
        f"print(g('jident_ros'))\")/lib/jident_ros/jident\" && "
        '"$exe" --help >/dev/null && echo "$exe"'
    )
    sourced = _run(["bash", "-c", script], env=sourced_env, cwd=tmp_path, timeout=120)
    assert sourced.returncode == 0, _explain(sourced)
    assert Path(sourced.stdout.strip()) == exe


# --------------------------------------------------------------------------- ROS runtime of the venv


@pytest.mark.ros
def test_rclpy_and_message_packages_work(ros_env, tmp_path):
    """The exec_depends of package.xml are importable and rclpy can start a node (rmw found)."""
    probe = textwrap.dedent(
        """
        import rclpy
        from std_msgs.msg import Float64MultiArray
        from diagnostic_msgs.msg import DiagnosticArray
        from rosgraph_msgs.msg import Clock
        rclpy.init()
        node = rclpy.create_node('jident_packaging_probe')
        print(node.get_name(), rclpy.get_default_context().get_domain_id())
        node.destroy_node()
        rclpy.shutdown()
        """
    )
    result = _run([sys.executable, "-c", probe], env=ros_env, cwd=tmp_path, timeout=120)
    assert result.returncode == 0, _explain(result)
    name, domain = result.stdout.split()
    assert name == "jident_packaging_probe"
    assert domain == ros_env["ROS_DOMAIN_ID"]
