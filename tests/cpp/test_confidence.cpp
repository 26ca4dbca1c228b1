// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Calibrated confidence and open-set rejection (confidence.hpp) on cases
// worked by hand: the temperature between knots, softmax probabilities, the
// threshold by sweep length, and the reserved label.
#include "tofmat/core/confidence.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <stdexcept>

#include "tofmat/core/exemplar_table.hpp"

namespace {

using namespace tofmat;

Classification ranking(std::initializer_list<Match> matches) {
  Classification c;
  c.ranking = matches;
  return c;
}

TEST(Calibration, InterpolatesInLogLengthAndHoldsBeyondTheEnds) {
  Calibration c;
  c.temperatures = {{1.0, 2.0}, {100.0, 6.0}};
  c.validate();
  EXPECT_DOUBLE_EQ(c.temperature(0.5), 2.0);
  EXPECT_DOUBLE_EQ(c.temperature(1.0), 2.0);
  EXPECT_DOUBLE_EQ(c.temperature(10.0), 4.0);  // half way in log length
  EXPECT_DOUBLE_EQ(c.temperature(1000.0), 6.0);
  EXPECT_EQ(c.unknown_fit(10.0), std::numeric_limits<double>::infinity());  // no thresholds: never
  c.unknown_fits = {{1.0, 1.0}, {10.0, 3.0}};
  EXPECT_DOUBLE_EQ(c.unknown_fit(std::sqrt(10.0)), 2.0);
}

TEST(Calibration, ProbabilitiesAreASoftmaxAtTheLengthsTemperature) {
  Calibration c;
  c.temperatures = {{1.0, 2.0}};
  // Scores 0 and 2 ln 2 at T = 2: weights 1 and 1/2.
  const auto v = judge(ranking({{0, 0.0, 4}, {1, 2.0 * std::log(2.0), 4}}), 2, c);
  ASSERT_EQ(v.probability.size(), 2u);
  EXPECT_NEAR(v.probability[0], 2.0 / 3.0, 1e-12);
  EXPECT_NEAR(v.probability[1], 1.0 / 3.0, 1e-12);
  EXPECT_NEAR(v.confidence(), 2.0 / 3.0, 1e-12);
  EXPECT_FALSE(v.unknown);
  // Scores far apart and far from zero neither overflow nor lose the best.
  const auto far = judge(ranking({{0, -1e6, 4}, {1, 1e300, 4}}), 2, c);
  EXPECT_EQ(far.probability[0], 1.0);
  EXPECT_EQ(far.probability[1], 0.0);
}

TEST(Calibration, ABestMatchThatFitsWorseThanItsNoiseFlattensTheProbabilities) {
  Calibration c;
  c.temperatures = {{1.0, 2.0}};
  // n = 9: a = 2/81. The deviate of Q/n = 8 is (2 - 1 + a) / sqrt(a): the temperature is 8 x 2.
  const double a = 2.0 / 81.0;
  const double z8 = (2.0 - 1.0 + a) / std::sqrt(a);
  EXPECT_NEAR(fit_tempering(Match{0, 0.0, 9, z8}), 8.0, 1e-9);
  const auto v = judge(ranking({{0, 0.0, 9, z8}, {1, 16.0 * std::log(2.0), 9, 40.0}}), 1, c);
  EXPECT_NEAR(v.probability[0], 2.0 / 3.0, 1e-9);  // weights 1 and 1/2 at T = 16
  // A fit as good as the noise allows, or better, leaves the temperature alone.
  EXPECT_DOUBLE_EQ(fit_tempering(Match{0, 0.0, 9, 0.0}), 1.0);
  EXPECT_DOUBLE_EQ(fit_tempering(Match{0, 0.0, 9, -3.0}), 1.0);
  // Eq. (12) (no fit) and a match of no elements are not tempered; an infinite fit flattens all.
  EXPECT_DOUBLE_EQ(fit_tempering(Match{0, 0.0, 9}), 1.0);
  EXPECT_DOUBLE_EQ(fit_tempering(Match{0, 0.0, 0, 2.0}), 1.0);
  EXPECT_DOUBLE_EQ(fit_tempering(Match{0, 0.0, 9, std::numeric_limits<double>::infinity()}), 1e6);
}

TEST(Calibration, ABestMatchThatFitsOnlyByItsWideNoiseIsNoConfidentLabel) {
  // A candidate 10 x noisier than the table's typical one whose fit is half what its own noise allows
  // (Q/n = 0.5) explains the query five times worse than the typical noise does: T x 5.
  Calibration c;
  c.temperatures = {{1.0, 2.0}};
  const double a = 2.0 / 81.0;
  const double z_half = (std::cbrt(0.5) - 1.0 + a) / std::sqrt(a);
  const Match vague{1, 0.0, 9, z_half};
  EXPECT_NEAR(fit_tempering(vague), 1.0, 1e-12);  // at its own noise: no tempering
  EXPECT_NEAR(fit_tempering(vague, 10.0), 5.0, 1e-9);
  // A vagueness under 1 (a candidate quieter than the typical) or NaN never sharpens the confidence.
  EXPECT_NEAR(fit_tempering(vague, 0.1), 1.0, 1e-12);
  EXPECT_NEAR(fit_tempering(vague, std::numeric_limits<double>::quiet_NaN()), 1.0, 1e-12);
  // judge() takes the best match's vagueness by its table index: the same ranking, other tables.
  const Classification cl = ranking({{1, 0.0, 9, z_half}, {0, 10.0 * std::log(2.0), 9, 40.0}});
  EXPECT_NEAR(judge(cl, 1, c).probability[0], 1.0 / (1.0 + std::pow(2.0, -5.0)), 1e-9);  // T = 2
  EXPECT_NEAR(judge(cl, 1, c, {1.0, 10.0}).probability[0], 2.0 / 3.0, 1e-9);             // T = 10
  EXPECT_NEAR(judge(cl, 1, c, {10.0, 1.0}).probability[0], 1.0 / (1.0 + std::pow(2.0, -5.0)), 1e-9);
  EXPECT_NEAR(judge(cl, 1, c, {1.0}).probability[0], 1.0 / (1.0 + std::pow(2.0, -5.0)), 1e-9);  // (short: 1)
}

TEST(Calibration, TheSweepsLengthChoosesTheThreshold) {
  Calibration c;
  c.temperatures = {{1.0, 1.0}};
  c.unknown_fits = {{1.0, 1.0}, {100.0, 20.0}};
  // One row: valid elements are bins. A fit of 5 is unknown at 1 bin, known at 100.
  EXPECT_TRUE(judge(ranking({{0, 0.0, 1, 5.0}}), 1, c).unknown);
  EXPECT_FALSE(judge(ranking({{0, 0.0, 100, 5.0}}), 1, c).unknown);
  // Two rows: 200 elements are 100 bins.
  EXPECT_FALSE(judge(ranking({{0, 0.0, 200, 5.0}}), 2, c).unknown);
  // Eq. (12) has no fit (NaN): never unknown.
  EXPECT_FALSE(judge(ranking({{0, 0.0, 1}}), 1, c).unknown);
}

TEST(Calibration, TunedSettingsAndBadOnesAreClearErrors) {
  const auto eq12 = Calibration::tuned("eq12");
  const auto session = Calibration::tuned("session");
  eq12.validate();
  session.validate();
  EXPECT_TRUE(eq12.unknown_fits.empty());
  EXPECT_EQ(session.unknown_fits.size(), 5u);
  EXPECT_THROW(Calibration::tuned("onnx"), std::invalid_argument);
  Calibration c;
  EXPECT_THROW(c.validate(), std::invalid_argument);  // no temperature
  c.temperatures = {{10.0, 1.0}, {3.0, 1.0}};
  EXPECT_THROW(c.validate(), std::invalid_argument);  // not increasing
  c.temperatures = {{1.0, 0.0}};
  EXPECT_THROW(c.validate(), std::invalid_argument);  // T not > 0
  c.temperatures = {{1.0, 1.0}};
  c.unknown_fits = {{1.0, std::nan("")}};
  EXPECT_THROW(c.validate(), std::invalid_argument);
}

TEST(Calibration, UnknownIsAReservedMaterialName) {
  EXPECT_THROW(validate_material_name(kUnknownLabel), std::invalid_argument);
  EXPECT_NO_THROW(validate_material_name("unknown2"));
}

TEST(Exemplars, ANameMaterialAtTagIsOneExemplarOfThatMaterial) {
  EXPECT_NO_THROW(validate_material_name("cork@30"));
  for (const char* bad : {"@30", "cork@", "cork@30@2", "unknown@30"})
    EXPECT_THROW(validate_material_name(bad), std::invalid_argument) << bad;
  EXPECT_EQ(exemplar_material("cork@30"), "cork");
  EXPECT_EQ(exemplar_material("cork"), "cork");
  const ExemplarTable t({"cork@0", "paper", "cork@30", "wood@0"}, {RowSpec{16, 120}}, BinSpec::linspace(600, 1200, 2),
                        std::vector<float>(8, 1.0f));
  EXPECT_TRUE(t.has_exemplars());
  EXPECT_EQ(t.distinct_materials(), (std::vector<std::string>{"cork", "paper", "wood"}));
  EXPECT_EQ(t.material_of(2), "cork");
  EXPECT_EQ(t.material_id(3), 2u);
  // a material names all its exemplars, an entry only itself; an entry twice is an error
  EXPECT_EQ(candidate_names_to_indices(t, {"wood", "cork"}), (std::vector<std::uint32_t>{3, 0, 2}));
  EXPECT_EQ(candidate_names_to_indices(t, {"cork@30"}), (std::vector<std::uint32_t>{2}));
  EXPECT_THROW(candidate_names_to_indices(t, {"cork", "cork@30"}), std::invalid_argument);
  EXPECT_THROW(candidate_names_to_indices(t, {"cork@10"}), std::invalid_argument);
  EXPECT_THROW(candidate_names_to_indices(t, {"cork@0@1"}), std::invalid_argument);
}

TEST(Exemplars, AMaterialRanksOnceByItsBestExemplarWithItsExemplarsProbabilitiesSummed) {
  const ExemplarTable t({"cork@0", "paper", "cork@30", "wood"}, {RowSpec{16, 120}}, BinSpec::linspace(600, 1200, 2),
                        std::vector<float>(8, 1.0f));
  const Classification c = ranking({{2, 1.0, 2}, {1, 1.5, 2}, {0, 2.0, 2}, {3, 4.0, 2}});
  Verdict v;
  v.probability = {0.4, 0.3, 0.2, 0.1};
  const auto r = rank_materials(c, v, t);
  ASSERT_EQ(r.size(), 3u);
  EXPECT_EQ(r[0].material, "cork");
  EXPECT_EQ(r[0].position, 0u);  // cork@30, the best of cork's
  EXPECT_NEAR(r[0].probability, 0.6, 1e-12);
  EXPECT_EQ(r[1].material, "paper");
  EXPECT_NEAR(r[1].probability, 0.3, 1e-12);
  EXPECT_EQ(r[2].material, "wood");
  EXPECT_EQ(r[2].position, 3u);
  // a table of one entry per material: the ranking as it was
  const ExemplarTable plain({"a", "b"}, {RowSpec{16, 120}}, BinSpec::linspace(600, 1200, 2),
                            std::vector<float>(4, 1.0f));
  EXPECT_FALSE(plain.has_exemplars());
  Verdict w;
  w.probability = {0.7, 0.3};
  const auto p = rank_materials(ranking({{1, 1.0, 2}, {0, 2.0, 2}}), w, plain);
  ASSERT_EQ(p.size(), 2u);
  EXPECT_EQ(p[0].material, "b");
  EXPECT_DOUBLE_EQ(p[0].probability, 0.7);
  EXPECT_THROW(rank_materials(ranking({{1, 1.0, 2}}), w, plain), std::invalid_argument);
}

}  // namespace
