"""check_job and run_job: job files with the library's stages, against `mcpost run`
on the same file (its outputs and its messages are the truth)."""
import json
import os
import subprocess

import mcpost
import pytest

from conftest import CLI, CORNELL, assert_close


def job_file(tmp, stages):
    path = tmp / "job.yaml"
    path.write_text("inputs:\n"
                    f"  noisy: {{dump: {CORNELL}/series/cornell_spp0064.exr}}\n"
                    f"  reference: {{image: {CORNELL}/cornell_reference.exr}}\n"
                    "output: out\n"
                    "stages:\n" + stages)
    return path


def test_run_job_matches_mcpost_run(tmp):
    job = job_file(tmp, "  - info: {input: noisy}\n"
                        "  - metrics: {input: noisy, reference: reference, maps: false}\n"
                        "  - estimate: {input: noisy, denoiser: nlm, output: est}\n")
    out = mcpost.run_job(job, output=tmp / "py")
    assert out == str(tmp / "py")
    subprocess.run([CLI, "run", str(job), "-o", str(tmp / "cli"), "--quiet"], check=True)
    for name in ("report.json", "est/estimate.json"):
        assert os.path.exists(tmp / "py" / name)
    py = json.loads((tmp / "py" / "est" / "estimate.json").read_text())
    cli = json.loads((tmp / "cli" / "est" / "estimate.json").read_text())
    for key in ("cdf_at_tau", "expected_mean_error", "blocks"):
        assert_close(py[key], cli[key], err_msg=key)
    py = json.loads((tmp / "py" / "report.json").read_text())["sections"]
    cli = json.loads((tmp / "cli" / "report.json").read_text())["sections"]
    assert [s["stage"] for s in py] == ["info", "metrics", "estimate"]
    assert [s["stage"] for s in py] == [s["stage"] for s in cli]
    assert_close(py[1]["mse"], cli[1]["mse"])
    assert py[1]["mse"] > 0


def test_check_job_raises_what_mcpost_run_check_prints(tmp):
    job = job_file(tmp, "  - estimate: {input: noisy, tau: -1}\n")
    with pytest.raises(mcpost.Error) as e:
        mcpost.check_job(job)
    cli = subprocess.run([CLI, "run", "--check", str(job)], capture_output=True, text=True)
    assert cli.returncode == 1
    assert cli.stderr == f"mcpost: {e.value}\n"
    assert "job.yaml:" in str(e.value)
    with pytest.raises(mcpost.Error) as e:
        mcpost.run_job(job)
    assert cli.stderr == f"mcpost: {e.value}\n"
    assert not os.path.exists(tmp / "out")  # checked before anything ran


def test_check_job_passes_a_good_job(tmp):
    assert mcpost.check_job(job_file(tmp, "  - info: {input: noisy}\n")) is None
    with pytest.raises(TypeError):
        mcpost.check_job(3)


def test_run_job_finds_mcposts_programs(tmp, monkeypatch):
    """An adaptive stage whose render command names mcpost-procedural without a path
    runs from Python with a PATH that lacks the build folder: the library finds the
    program among mcpost's own (common/core/shell.c), and it spends the budget."""
    job = tmp / "adaptive.yaml"
    job.write_text("output: out\n"
                   "stages:\n"
                   "  - adaptive:\n"
                   "      render: \"mcpost-procedural --sample-counts {counts} --pass {pass}"
                   " --seed {seed} -o {output}\"\n"
                   "      size: 16x16\n"
                   "      budget: 8\n"
                   "      spp_per_iteration: 4\n"
                   "      denoiser: gauss\n")
    monkeypatch.setenv("PATH", "/usr/bin:/bin")
    out = mcpost.run_job(job, output=tmp / "py")
    result = json.loads((tmp / "py" / "adaptive" / "adaptive.json").read_text())
    assert out == str(tmp / "py")
    assert result["iterations"][-1]["total_samples"] == 8 * 16 * 16
