"""numba's kernel cache follows the law it inlines (persival.model.fe.kernel_cache)."""

from persival.model.fe.kernel_cache import drop_stale_kernels


def test_cached_kernels_are_dropped_when_a_dependency_changes(tmp_path):
    module, law = tmp_path / "assembly.py", tmp_path / "material.py"
    module.write_text("# kernels")
    law.write_text("S = 1")
    cache = tmp_path / "__pycache__"
    cache.mkdir()

    def compiled():
        for name in ("assembly._kernel-1.py311.nbi", "assembly._kernel-1.py311.1.nbc"):
            (cache / name).write_text("binary")
        (cache / "material._law-1.py311.nbi").write_text("binary")  # another module's: never touched

    compiled()
    assert drop_stale_kernels(str(module), [str(law)])  # no record of the law yet: dropped
    assert not list(cache.glob("assembly.*.nb*")) and (cache / "material._law-1.py311.nbi").exists()
    compiled()
    assert not drop_stale_kernels(str(module), [str(law)])  # same law: kept
    assert len(list(cache.glob("assembly.*.nb*"))) == 2
    law.write_text("S = 2")  # the law changed: the kernels compiled with the old one go
    assert drop_stale_kernels(str(module), [str(law)])
    assert not list(cache.glob("assembly.*.nb*"))
