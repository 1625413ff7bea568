"""Speech benchmark: real-time factor of the service path vs the bare pocketsphinx decoder on the same
audio, and end of utterance -> Transcript received over Zenoh (p50/p99).

    .venv/bin/python benchmarks/speech.py [--utterances N]

Audio: espeak-ng commands (voice en-us+f3) made on the spot. "bare" = one pocketsphinx decoder with
the same grammar on each command's WAV, nothing else. "core" = the service's pipeline in-process
(20 ms chunks -> silero VAD -> recogniser -> checks). "service" = the real process, AudioChunks
published at real-time pace over a local router.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from common.codec import decode  # noqa: E402
from common.schema import AudioChunk, Transcript  # noqa: E402
from services.speech.audio import read_wav  # noqa: E402
from services.speech.pipeline import MicStream  # noqa: E402
from services.speech.recognizers import PocketsphinxRecognizer  # noqa: E402
from services.speech.synth import concatenate, read_wav_int16, synthesize  # noqa: E402
from services.speech.vad import VadConfig, make_segmenter  # noqa: E402
from tests.harness import Client, ProcessGroup  # noqa: E402

COMMANDS = [line.strip() for line in (ROOT / "tests/data/speech/commands.txt").read_text().splitlines() if line]


def pct(values: list[float], q: float) -> float:
    return float(np.percentile(values, q)) if values else float("nan")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--utterances", type=int, default=12, help="how many commands (default 12)")
    args = parser.parse_args()
    texts = (COMMANDS * (args.utterances // len(COMMANDS) + 1))[:args.utterances]
    with tempfile.TemporaryDirectory(prefix="hri-bench-speech-") as tmp:
        print(f"synthesising {len(texts)} commands with espeak-ng ...", flush=True)
        files = [synthesize(t, Path(tmp) / f"{i:02d}.wav", voice="en-us+f3") for i, t in enumerate(texts)]
        stream_path = concatenate(files, Path(tmp) / "stream.wav", gap=1.0)
        audio_seconds = sum(len(read_wav_int16(f)) for f in files) / 16000
        rec = PocketsphinxRecognizer(min_confidence=0.0)

        # bare decoder: the same grammar search on each file through pocketsphinx's own calls, nothing
        # around it (no VAD, no phone-loop confidence, no checks)
        pcm = [read_wav_int16(f).tobytes() for f in files]
        decoder = rec.decoder
        decoder.activate_search("commands")
        t = time.perf_counter()
        for p in pcm:
            decoder.start_utt()
            decoder.process_raw(p, False, True)
            decoder.end_utt()
            decoder.hyp()
        bare = time.perf_counter() - t

        # core path: chunks -> resampler/VAD -> recogniser -> grammar and confidence checks
        wav = read_wav(stream_path)
        stream = MicStream("bench", "bench/0", rec, make_segmenter, lambda n, d: None)
        t = time.perf_counter()
        heard = []
        for off in range(0, len(wav.samples), 320):
            heard += stream.feed(wav.samples[off:off + 320], 16000, 1e9 + off / 16000)
        heard += stream.flush()
        core = time.perf_counter() - t
        print("\nreal-time factor (compute seconds per audio second; lower is faster)")
        print(f"  bare decoder, {len(files)} files, {audio_seconds:.1f} s of audio : RTF {bare / audio_seconds:.3f}")
        print(f"  service core, one {wav.seconds:.1f} s stream (VAD + decode)  : RTF {core / wav.seconds:.3f} "
              f"({len(heard)} transcripts)")

        # the real process over zenoh, fed at real-time pace; arrival wall times taken in the callback
        arrivals: list[tuple[float, Transcript]] = []
        samples = read_wav_int16(stream_path)
        group = ProcessGroup()
        client = None
        try:
            group.router()
            group.service("speech", "--input", "zenoh")
            client = Client(group.endpoint)
            client.wait_alive("speech")
            sub = client.session.declare_subscriber(
                "hri/speech/*/transcript",
                lambda s: arrivals.append((time.time(), decode(s.payload.to_bytes(), Transcript))))
            print(f"\nplaying {len(samples) / 16000:.1f} s over zenoh at real-time pace ...", flush=True)
            t0 = time.time() + 0.2
            step = 320  # 20 ms chunks, each stamped with the time it is sent
            for off in range(0, len(samples), step):
                due = t0 + off / 16000
                if due > time.time():
                    time.sleep(due - time.time())
                client.publish(client.keys.audio("bench"), AudioChunk(
                    stamp=due, source="bench/mic", mic="bench", rate=16000, channels=1, format="s16le",
                    data=samples[off:off + step].astype("<i2").tobytes()))
            time.sleep(2.0)
            sub.undeclare()
        finally:
            if client is not None:
                client.close()
            group.close()
        hangover = VadConfig.min_silence
        from_speech_end = [(arrived - t.end) * 1000 for arrived, t in arrivals]
        # the VAD can only decide `min_silence` after the speech ends; its decision is when the chunk
        # carrying that sample was sent (chunks are stamped with their send time)
        from_decision = [(arrived - (t.end + hangover)) * 1000 for arrived, t in arrivals]
        print(f"\nend of utterance -> Transcript received ({len(arrivals)} transcripts)")
        print(f"  from the VAD's end decision (speech end + {hangover * 1000:.0f} ms silence): "
              f"p50 {pct(from_decision, 50):.0f} ms  p99 {pct(from_decision, 99):.0f} ms  (target <= 300 ms)")
        print(f"  from the last spoken word's end                        : "
              f"p50 {pct(from_speech_end, 50):.0f} ms  p99 {pct(from_speech_end, 99):.0f} ms")


if __name__ == "__main__":
    main()
