"""Precision ``auto``: bf16 only where the CPU computes it natively, a warning where bf16 is asked for without it."""

from __future__ import annotations

import json

import pytest

from adaptenv.agents import network
from adaptenv.agents.network import native_bf16, resolve_precision, same_arithmetic
from adaptenv.agents.train import train
from tests.agents.test_train import tiny_config

AVX2_EPYC = """processor\t: 0
vendor_id\t: AuthenticAMD
model name\t: AMD EPYC 7B13 64-Core Processor
flags\t\t: fpu vme de pse tsc msr pae mce cx8 apic sse sse2 ssse3 fma cx16 sse4_1 sse4_2 avx f16c avx2 bmi2
"""
ZEN5 = AVX2_EPYC.replace("avx2 bmi2", "avx2 bmi2 avx512f avx512bw avx512_bf16 avx512_vnni")
SAPPHIRE_RAPIDS = AVX2_EPYC.replace("avx2 bmi2", "avx2 avx512f amx_bf16 amx_tile amx_int8")
GRAVITON3 = "processor\t: 0\nFeatures\t: fp asimd evtstrm aes pmull sha1 sha2 crc32 atomics bf16 i8mm sve\n"
GRAVITON2 = "processor\t: 0\nFeatures\t: fp asimd evtstrm aes pmull sha1 sha2 crc32 atomics\n"


@pytest.mark.parametrize(("cpuinfo", "machine", "native"), [
    (AVX2_EPYC, "x86_64", False), (ZEN5, "x86_64", True), (SAPPHIRE_RAPIDS, "AMD64", True),
    (GRAVITON3, "aarch64", True), (GRAVITON2, "aarch64", False), (GRAVITON3, "arm64", True),
    (ZEN5, "riscv64", False),  # another architecture: never bf16
    ("", "x86_64", False),
])
def test_native_bf16_reads_the_cpu_flags(cpuinfo, machine, native):
    assert native_bf16(cpuinfo, machine) is native


def test_the_bf16_flag_of_another_architecture_does_not_count():
    assert not native_bf16(GRAVITON3, "x86_64")  # 'bf16' alone is an arm feature, not an x86 flag
    assert not native_bf16(ZEN5.replace("flags", "bugs"), "x86_64")  # only the flags line counts


@pytest.fixture
def fp32_cpu(monkeypatch):
    """This machine as an AVX2-only CPU, the warning not yet given in this process."""
    monkeypatch.setattr(network, "auto_precision", lambda: "fp32")
    network._warned_slow_bf16.clear()
    yield
    network._warned_slow_bf16.clear()


def test_auto_is_fp32_and_an_explicit_bf16_warns_once_on_a_cpu_without_it(fp32_cpu, capsys):
    assert resolve_precision("auto") == "fp32"
    assert resolve_precision("fp32") == "fp32"
    assert capsys.readouterr().err == ""
    assert resolve_precision("bf16") == resolve_precision("bf16") == "bf16"
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 1
    assert "--precision bf16 on a CPU without native bf16" in lines[0] and "about 8 times slower" in lines[0]
    assert resolve_precision("bf16", "--finetune-precision") == "bf16"  # once per process, whichever option
    assert capsys.readouterr().err == ""
    assert same_arithmetic("fp32", "auto") and not same_arithmetic("bf16", "auto")


def test_auto_is_bf16_where_the_cpu_has_it_and_bf16_then_says_nothing(monkeypatch, capsys):
    monkeypatch.setattr(network, "auto_precision", lambda: "bf16")
    network._warned_slow_bf16.clear()
    assert resolve_precision("auto") == resolve_precision("bf16") == "bf16"
    assert capsys.readouterr().err == ""


def test_the_card_records_the_precision_used(fp32_cpu, tmp_path):
    result = train(tiny_config(tmp_path, frames=512, final_eval_episodes=1))
    assert result.card["config"]["precision"] == "auto"  # what was asked
    assert result.card["precision"] == "fp32"  # what ran
    assert json.loads((tmp_path / "p.json").read_text())["precision"] == "fp32"
