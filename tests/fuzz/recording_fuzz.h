// One fuzz entry point over the recording-set readers, shared by the
// libFuzzer build (scripts/fuzz.sh, clang) and the GoogleTest-driven
// mutational run in ctest (fuzz_test.cc, any compiler).
//
// Input layout: the first byte picks which file of a small valid set the
// rest of the input replaces (manifest.json, the waveform, steady_state.csv,
// hf_results.csv); so every mutation starts from a set that reads.
// Invariant checked on every input: the reader returns (never crashes), and
// a rejection names a file of the set followed by ':' and is printable
// (no control bytes, valid UTF-8 for JSON and logs). A violation aborts.
#ifndef FLUXCAL_TESTS_FUZZ_RECORDING_FUZZ_H_
#define FLUXCAL_TESTS_FUZZ_RECORDING_FUZZ_H_

#include <cstddef>
#include <cstdint>
#include <string>

#include "io/recording_set.h"

namespace fluxcal::fuzz {

// The base set: manifest, one locked point of 200 samples (10 periods of
// 500 Hz injection at 10 kHz), two steady-state rows, two HF rows.
const io::RecordingFiles& BaseSet();

// Names of the files an input byte selects (index = byte % size).
inline constexpr const char* kTargets[] = {"manifest.json", "points/p000.csv", "steady_state.csv",
                                           "hf_results.csv"};

// Runs one input; returns 1 when the set was accepted, 0 when rejected with
// a well-formed message. Aborts (std::abort) on a malformed rejection.
int RunOne(const uint8_t* data, size_t size);

// An input for target `t` whose payload is `payload`.
std::string MakeInput(size_t t, const std::string& payload);

}  // namespace fluxcal::fuzz

#endif  // FLUXCAL_TESTS_FUZZ_RECORDING_FUZZ_H_
