#include "tests/fuzz/recording_fuzz.h"

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <numbers>
#include <string_view>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "io/csv.h"

namespace fluxcal::fuzz {
namespace {

io::RecordingFiles MakeBase() {
  io::RecordingFiles f;
  f["manifest.json"] = R"({
  "format": "fluxcal.recording.v1",
  "serial": "IPM-FUZZ-1",
  "motor": { "pole_pairs": 4, "rs_ohm": 0.011, "psi_pm_wb": 0.0089 },
  "drive": { "udc_v": 50.0, "f_pwm_hz": 10000.0, "f_sample_hz": 10000.0,
             "dead_time_s": 1e-6, "dead_time_compensated": true },
  "injection": { "type": "rotating", "amplitude_v": 5.0, "frequency_hz": 500.0 },
  "points": [ { "id": "p000", "file": "points/p000.csv", "id_ref_a": -20.0,
                "iq_ref_a": 40.0, "speed_rpm": 0.0, "temperature_c": 25.0 } ],
  "steady_state": "steady_state.csv",
  "hf_results": "hf_results.csv"
}
)";
  std::string w = "t_s,ia_a,ib_a,ic_a,theta_e_rad,ualpha_ref_v,ubeta_ref_v,udc_v\n";
  for (int k = 0; k < 200; ++k) {
    const double t = k / 10000.0, ph = 2 * std::numbers::pi * 500.0 * t;
    absl::StrAppend(&w, absl::StrFormat("%.6g,%.6g,%.6g,%.6g,0.3,%.6g,%.6g,%s\n", t, 10 * std::cos(ph),
                                        10 * std::cos(ph - 2.0944), 10 * std::cos(ph + 2.0944),
                                        5 * std::cos(ph), 5 * std::sin(ph), k % 2 ? "50.01" : ""));
  }
  f["points/p000.csv"] = w;
  f["steady_state.csv"] =
      "id_a,iq_a,speed_rpm,ud_ref_v,uq_ref_v,torque_nm,temperature_c\n"
      "-20,60,1000,-10.5,20.25,8.5,25\n0,40,2000,-12.5,22.25,,\n";
  f["hf_results.csv"] =
      "id_a,iq_a,speed_rpm,ld_h,lq_h,ldq_h,temperature_c\n"
      "-20,40,0,1.8e-4,3.5e-4,-1e-5,25\n0,0,0,1.9e-4,3.7e-4,,\n";
  return f;
}

bool IsPrintable(std::string_view s) {
  for (unsigned char c : s) {
    if (c < 0x20 || c == 0x7f) return false;
  }
  // Valid UTF-8: io::Printable escapes everything else, so the message must
  // equal its own escaping.
  return io::Printable(s) == s;
}

[[noreturn]] void Fail(const std::string& why, std::string_view input) {
  std::fprintf(stderr, "fuzz invariant violated: %s (input %zu bytes)\n", why.c_str(), input.size());
  std::abort();
}

}  // namespace

const io::RecordingFiles& BaseSet() {
  static const io::RecordingFiles base = MakeBase();
  return base;
}

std::string MakeInput(size_t t, const std::string& payload) {
  return std::string(1, static_cast<char>(t)) + payload;
}

int RunOne(const uint8_t* data, size_t size) {
  if (size == 0) return 0;
  constexpr size_t kN = sizeof(kTargets) / sizeof(kTargets[0]);
  const std::string target = kTargets[data[0] % kN];
  io::RecordingFiles files = BaseSet();
  files[target].assign(reinterpret_cast<const char*>(data) + 1, size - 1);
  auto set = io::ReadRecordingSetFromFiles(files, "");
  const std::string_view input(reinterpret_cast<const char*>(data), size);
  if (set.ok()) {
    // Whatever was accepted is internally consistent.
    if (set->waveforms.size() != set->manifest.points.size()) Fail("waveforms != points", input);
    for (const auto& w : set->waveforms) {
      if (w.ia_a.size() != w.size() || w.udc_v.size() != w.size()) Fail("ragged waveform", input);
    }
    return 1;
  }
  const std::string msg(set.status().message());
  if (!IsPrintable(msg)) Fail("message is not printable: " + io::Printable(msg), input);
  bool names_file = false;
  for (const char* f : kTargets) {
    if (msg.rfind(absl::StrCat(f, ":"), 0) == 0) names_file = true;
  }
  if (!names_file) Fail("message does not start with a file of the set: " + msg, input);
  if (msg.find("field '") == std::string::npos && msg.find(": referenced file") == std::string::npos) {
    Fail("message names no field: " + msg, input);
  }
  return 0;
}

}  // namespace fluxcal::fuzz
