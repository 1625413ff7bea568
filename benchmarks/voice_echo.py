"""The robot's own voice on its microphone (issue #43, docs/voice.md): the speech service's pipeline in-process
(MicStream with OwnVoice: the announced spans masked, the echo cancelled, only a stop kept), fed what a robot's
microphone hears in a room (testkit/room.py: its piper-spoken question through a living room's response, background
noise) with and without a real person's word said over it (../shared/data/speech_commands/).

For each stop clip: one robot that first asks a question alone (the own-voice check: anything heard is a failure;
the echo path is learnt here) and then asks another with the stop said over it at a given level against the
echo (the barge-in check), for -6 dB and 0 dB. Then other words (go, no) over a question: anything published is a
false transcript (a "stop" a false stop). Split: the stops of the five speakers whose ids sort first are the
development set, the other five held back (reported apart).

    .venv/bin/python benchmarks/voice_echo.py [--ratios -6,0] [--others go,no] [--mic-gain G]

--mic-gain: the microphone's gain over the room (testkit/room.py MIC_GAIN, set so that the robot's voice does not
clip a 16-bit microphone); 4 is the level measured before 29 Nov (the echo then went up to 2.6x full scale, kept
in float here: a microphone with headroom no real one has).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

QUESTIONS = (
    "Which candy: the red one on the left or the green one on the right?",
    "Which cup: the red one or the blue one?",
    "I can't pick up a chair.",
    "Where do you mean? Please point at the place.",
)


def main() -> int:
    from services.speech.echo import OwnVoice
    from services.speech.pipeline import MicStream
    from services.speech.vad import make_segmenter
    from services.speech.whisper import WhisperRecognizer
    from services.voice.synth import PiperVoice
    from testkit.room import MIC_GAIN, hear, room_response, scene
    from testkit.synth import read_wav_int16

    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--ratios", default="-6,0", help="person against echo, dB")
    parser.add_argument("--others", default="go,no", help="non-stop words said over the robot")
    parser.add_argument("--mic-gain", type=float, default=1.0, help="times testkit/room.py's MIC_GAIN")
    args = parser.parse_args()
    gain = MIC_GAIN * args.mic_gain
    print(f"microphone gain {gain:g} over the room", flush=True)
    shared = ROOT.parent / "shared" / "data" / "speech_commands"
    stops = sorted(shared.glob("stop_*.wav"))
    if not stops:
        print(f"no stop clips under {shared}")
        return 1
    voice = PiperVoice()
    questions = [voice.speak(q) for q in QUESTIONS]
    recogniser = WhisperRecognizer()
    recogniser.recognise(np.zeros(8000, np.float32))
    ir = room_response()
    counts: dict[str, int] = {}

    def robot() -> tuple[MicStream, OwnVoice]:
        own = OwnVoice()
        stream = MicStream("mic0", "bench", recogniser, make_segmenter, lambda name, detail: None, own_voice=own)
        return stream, own

    def clip(path: Path) -> np.ndarray:
        return read_wav_int16(path).astype(np.float64) / 32768.0

    def run(j: int, path: Path, ratio: float) -> tuple[list[str], list[str]]:
        stream, own = robot()
        t0 = 1.8e9 + 100 * j
        q0, q1 = (j + 1) % len(QUESTIONS), j % len(QUESTIONS)
        alone = hear(stream, own, scene(questions[q0], None, 0, 0, ir, gain=gain), questions[q0], t0, QUESTIONS[q0], 0)
        length = len(questions[q1]) / 16000
        at = 0.2 + 0.6 * ((j * 0.37) % 1) * max(0.0, length - 1.0)  # somewhere in its question, spread
        mic = scene(questions[q1], clip(path), at, ratio, ir, gain=gain)
        over = hear(stream, own, mic, questions[q1], t0 + 20, QUESTIONS[q1], 1)
        return [t.text for t in alone], [t.text for t in over]

    started = time.monotonic()
    for ratio in [float(r) for r in args.ratios.split(",")]:
        for part, clips in (("development", stops[:5]), ("held back", stops[5:])):
            got = [run(j + (5 if part == "held back" else 0), p, ratio) for j, p in enumerate(clips)]
            stopped = sum(over == ["stop"] for _, over in got)
            heard_alone = sum(len(alone) for alone, _ in got)
            print(
                f"{ratio:+.0f} dB, {part}: stops {stopped}/{len(got)}; the question alone heard as words {heard_alone}"
            )
            for (alone, over), p in zip(got, clips):
                print(f"    {p.name}: alone {alone}, over {over}")
            counts[f"{ratio}/{part}"] = stopped
    for word in [w for w in args.others.split(",") if w]:
        clips = sorted(shared.glob(f"{word}_*.wav"))
        published = [run(j, p, 0.0)[1] for j, p in enumerate(clips)]
        print(f"'{word}' over the robot (0 dB): published {sum(map(len, published))} of {len(clips)} ({published})")
    print(f"({time.monotonic() - started:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
