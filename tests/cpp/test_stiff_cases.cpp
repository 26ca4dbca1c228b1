// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Every stiff case of stiff_cases.hpp within the budget docs/numerics.md
// states, and the cases live: each compared something and the errors that
// must appear (the quantisation's) do.
#include "stiff_cases.hpp"

#include <gtest/gtest.h>

#include <iostream>
#include <set>
#include <string>

namespace {

using tofmat_test::StiffRow;

const std::vector<StiffRow>& rows() {
  static const std::vector<StiffRow> r = tofmat_test::stiff_cases(20000);
  return r;
}

TEST(StiffCases, EveryCaseIsWithinItsBudget) {
  for (const StiffRow& r : rows()) {
    EXPECT_TRUE(r.within()) << r.stage << ", " << r.scenario << ": " << r.quantity << " " << r.worst << " > "
                            << r.budget;
  }
  std::cout << tofmat_test::stiff_cases_markdown(rows());
}

TEST(StiffCases, EveryCaseComparedSomething) {
  for (const StiffRow& r : rows()) {
    EXPECT_GT(r.compared, 0u) << r.stage << ", " << r.scenario << ": " << r.quantity;
  }
}

TEST(StiffCases, TheCasesTheIssueNamesAreThere) {
  std::set<std::string> names;
  for (const StiffRow& r : rows()) names.insert(r.scenario);
  for (const char* s :
       {"near-zero amplitude", "saturation", "largest magnitudes", "wrap points", "range ends", "tiny tau (1 ps)",
        "huge tau (100 ns), half the light", "huge tau (100 ns), all the light", "one valid element",
        "about 2^20 observations a bin", "widest window at the extremes", "window wider than the frame"}) {
    EXPECT_TRUE(names.count(s)) << s;
  }
}

TEST(StiffCases, TheQuantisationShows) {
  // The comparisons are live: depths and window means carry their Q16 / Q8
  // rounding, so a zero error would mean the two sides were the same code.
  bool depth = false, box = false;
  for (const StiffRow& r : rows()) {
    if (r.quantity == "per-frequency depth, mm" && r.worst > 0) depth = true;
    if (r.quantity == "window mean, mm" && r.worst > 0) box = true;
  }
  EXPECT_TRUE(depth);
  EXPECT_TRUE(box);
}

TEST(StiffCases, HugeTauDistortsButKeepsHalfTheLightValid) {
  // Half the light 100 ns late: the pixels stay valid (depths compared), and
  // their features show the distortion the classifier reads.
  std::size_t compared = 0;
  for (const StiffRow& r : rows()) {
    if (r.scenario == "huge tau (100 ns), half the light" && r.quantity == "features (Eq. 10), mm")
      compared = r.compared;
  }
  EXPECT_GT(compared, 15000u);  // of 20000 pixels
}

TEST(StiffCases, TheTableIsMarkdown) {
  const std::string md = tofmat_test::stiff_cases_markdown(rows());
  EXPECT_EQ(md.rfind("## Stiff cases\n", 0), 0u);
  EXPECT_NE(md.find("| stage | case | inputs | compared | quantity | worst error | budget | within budget |"),
            std::string::npos);
  std::size_t lines = 0;
  for (char c : md) lines += c == '\n';
  EXPECT_EQ(lines, rows().size() + 4);
}

}  // namespace
