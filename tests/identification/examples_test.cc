// Identification on the independent example sets against their truth files
// (a check, not a target: the tolerance is the round-trip figure).
#include <filesystem>
#include <fstream>

#include "gtest/gtest.h"
#include "identification/identify.h"
#include "nlohmann/json.hpp"

namespace fluxcal::ident {
namespace {

namespace fs = std::filesystem;

TEST(Examples, CleanSetWithinHalfPercentBothMethods) {
  const fs::path root = fs::path(FLUXCAL_SHARED_DIR) / "examples";
  if (!fs::exists(root / "clean")) GTEST_SKIP() << "no shared examples";
  auto set = io::ReadRecordingSet((root / "clean").string());
  ASSERT_TRUE(set.ok()) << set.status();
  std::ifstream tf(root / "clean.truth.json");
  const auto truth = nlohmann::json::parse(tf);
  std::map<std::string, nlohmann::json> tp;
  for (const auto& p : truth["points"]) tp[p["id"].get<std::string>()] = p;
  for (Method m : {Method::kLsq, Method::kPaper}) {
    IdentifyOptions opt;
    opt.method = m;
    auto res = IdentifySet(*set, opt);
    ASSERT_TRUE(res.ok()) << res.status();
    for (const auto& r : *res) {
      const auto& t = tp.at(r.point);
      const double tol = t["speed_rpm"].get<double>() > 1200 ? 0.012 : 0.005;
      EXPECT_NEAR(r.ld_h / t["ldd_h"].get<double>(), 1.0, tol) << MethodName(m) << " " << r.point;
      EXPECT_NEAR(r.lq_h / t["lqq_h"].get<double>(), 1.0, tol) << MethodName(m) << " " << r.point;
    }
  }
}

}  // namespace
}  // namespace fluxcal::ident
