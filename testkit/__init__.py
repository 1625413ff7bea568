"""Test support, imported by tests/ and benchmarks/ (and the demo's synthesised voice): the process harness
(`harness`), the fusion scenario suite (`scenarios`), the contract's example samples (`examples`, `payloads`),
text-to-speech for tests (`synth`), speech scoring, the fuzzer, network namespaces, a headless browser, the
real test material of ../shared (`shared`) and the tool that records tests/data (`record_landmarks`).

Nothing shipped (common/, services/, hri/) imports it: tests/test_layers.py checks.
"""
