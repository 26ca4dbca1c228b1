// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The learned classifier's model contract, and its onnxruntime path against
// the NumPy reference (tests/cpp/data/onnx, written by make_fixture.py). A
// build without onnxruntime's headers is checked to refuse clearly instead.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <memory>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "tofmat/core/npy.hpp"
#include "tofmat/learn/model_contract.hpp"
#include "tofmat/learn/onnx_classifier.hpp"

namespace {

using tofmat::ExemplarTable;
using tofmat::learn::ModelContract;
using tofmat::learn::OnnxClassifier;

const std::filesystem::path kData = TOFMAT_ONNX_FIXTURE_DIR;

std::shared_ptr<const ExemplarTable> real_table() {
  static const auto table = std::make_shared<const ExemplarTable>(
      ExemplarTable::from_npy_dir(TOFMAT_DB_DIR, tofmat::kDatabaseBinStartMm, tofmat::kDatabaseBinStopMm));
  return table;
}

std::map<std::string, std::string> good_metadata() {
  return {{"tofmat.contract", "1.0"},
          {"tofmat.materials", "cork\nwood"},
          {"tofmat.rows", "2"},
          {"tofmat.bins", "600.0 3.0150753768844223 200"}};
}

std::string refusal(const std::map<std::string, std::string>& md) {
  try {
    tofmat::learn::parse_contract(md);
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  return "";
}

TEST(ModelContract, ParsesTheMetadata) {
  const ModelContract c = tofmat::learn::parse_contract(good_metadata());
  EXPECT_EQ(c.major, 1);
  EXPECT_EQ(c.minor, 0);
  EXPECT_EQ(c.materials, (std::vector<std::string>{"cork", "wood"}));
  EXPECT_EQ(c.rows, 2U);
  EXPECT_EQ(c.bins.count, 200U);
  EXPECT_DOUBLE_EQ(c.bins.width_mm, 3.0150753768844223);
  EXPECT_TRUE(c.temperatures.empty());
  auto with_t = good_metadata();
  with_t["tofmat.temperatures"] = "1:2.5 10:1.25  100:0.5";
  EXPECT_EQ(tofmat::learn::parse_contract(with_t).temperatures,
            (std::vector<std::pair<double, double>>{{1, 2.5}, {10, 1.25}, {100, 0.5}}));
  auto newer = good_metadata();
  newer["tofmat.contract"] = "1.7";  // a newer minor runs
  EXPECT_EQ(tofmat::learn::parse_contract(newer).minor, 7);
}

TEST(ModelContract, RefusesWhatIsMissingOrMalformed) {
  for (const char* key : {"tofmat.contract", "tofmat.materials", "tofmat.rows", "tofmat.bins"}) {
    auto md = good_metadata();
    md.erase(key);
    EXPECT_NE(refusal(md).find(key), std::string::npos) << key;
  }
  const std::vector<std::pair<std::string, std::string>> bad = {
      {"tofmat.contract", "2.0"},
      {"tofmat.contract", "1"},
      {"tofmat.contract", "x.0"},
      {"tofmat.contract", "-1.0"},
      {"tofmat.materials", ""},
      {"tofmat.materials", "a\n\nb"},
      {"tofmat.rows", "0"},
      {"tofmat.rows", "-2"},
      {"tofmat.rows", "99999999999"},
      {"tofmat.rows", "2x"},
      {"tofmat.bins", "600 3"},
      {"tofmat.bins", "600 3 200 1"},
      {"tofmat.bins", "600 -3 200"},
      {"tofmat.bins", "600 nan 200"},
      {"tofmat.bins", "600 3 0"},
      {"tofmat.materials", std::string(tofmat::learn::kMaxMetadataValue + 1, 'a')},
      {"tofmat.temperatures", "1:2 1:3"},
      {"tofmat.temperatures", "1:0"},
      {"tofmat.temperatures", "1:nan"},
      {"tofmat.temperatures", "1"},
      {"tofmat.temperatures", "1:2x"},
      {"tofmat.temperatures", ":2"},
      {"tofmat.temperatures", "-1:2"},
      {"tofmat.temperatures", "1e999:2"},
  };
  for (const auto& [key, value] : bad) {
    auto md = good_metadata();
    md[key] = value;
    EXPECT_FALSE(refusal(md).empty()) << key << " = " << value.substr(0, 40);
  }
  auto many = good_metadata();
  std::string names;
  for (std::size_t i = 0; i <= tofmat::learn::kMaxMaterials; ++i) names += "m" + std::to_string(i) + "\n";
  many["tofmat.materials"] = names;
  EXPECT_NE(refusal(many).find("more than"), std::string::npos);
}

TEST(ModelContract, ChecksTheTable) {
  const auto table = real_table();
  ModelContract c;
  c.materials = table->materials();
  c.rows = table->n_rows();
  c.bins = table->bins();
  EXPECT_NO_THROW(tofmat::learn::check_table(c, *table));
  auto swapped = c;
  std::swap(swapped.materials[0], swapped.materials[1]);
  EXPECT_THROW(tofmat::learn::check_table(swapped, *table), std::invalid_argument);
  auto fewer = c;
  fewer.materials.pop_back();
  EXPECT_THROW(tofmat::learn::check_table(fewer, *table), std::invalid_argument);
  auto rows = c;
  rows.rows = 3;
  EXPECT_THROW(tofmat::learn::check_table(rows, *table), std::invalid_argument);
  auto shifted = c;
  shifted.bins.start_mm += 1.0;
  EXPECT_THROW(tofmat::learn::check_table(shifted, *table), std::invalid_argument);
  // The curves' CRC: the table's own passes, another's is refused.
  auto crc = c;
  crc.curves_crc32 = tofmat::learn::curves_crc32(*table);
  EXPECT_NO_THROW(tofmat::learn::check_table(crc, *table));
  crc.curves_crc32 = *crc.curves_crc32 ^ 1U;
  EXPECT_THROW(tofmat::learn::check_table(crc, *table), std::invalid_argument);
  auto md = good_metadata();
  md["tofmat.curves_crc32"] = "0a1b2c3d";
  EXPECT_EQ(tofmat::learn::parse_contract(md).curves_crc32, 0x0a1b2c3dU);
  for (const char* bad : {"0A1B2C3D", "a1b2c3d", "0a1b2c3d0", "0x1b2c3d", ""}) {
    md["tofmat.curves_crc32"] = bad;
    EXPECT_FALSE(refusal(md).empty()) << bad;
  }
}

#ifdef TOFMAT_ONNXRUNTIME_LIBRARY

const std::string kLibrary = TOFMAT_ONNXRUNTIME_LIBRARY;

TEST(OnnxClassifier, MatchesTheReferenceNetwork) {
  ASSERT_TRUE(tofmat::learn::onnxruntime_built());
  const OnnxClassifier clf(real_table(), (kData / "tiny_mlp.onnx").string(), {}, kLibrary);
  EXPECT_EQ(clf.contract().materials, real_table()->materials());
  // The SDK wrote the curves' CRC (tofmat.learn.model.curves_crc32): the same as this one's.
  EXPECT_EQ(clf.contract().curves_crc32, tofmat::learn::curves_crc32(*real_table()));
  const auto q = tofmat::read_npy_file(kData / "queries.npy");
  const auto want = tofmat::read_npy_file(kData / "expected.npy");
  ASSERT_EQ(q.shape.size(), 2U);
  const std::size_t n = q.shape[1], m = want.shape[1];
  ASSERT_EQ(m, real_table()->n_materials());
  for (std::size_t i = 0; i < q.shape[0]; ++i) {
    std::vector<float> query(n);
    for (std::size_t k = 0; k < n; ++k) query[k] = static_cast<float>(q.data[i * n + k]);
    const auto p = clf.probabilities(query.data(), n);
    ASSERT_EQ(p.size(), m);
    double sum = 0.0;
    for (std::size_t j = 0; j < m; ++j) {
      EXPECT_NEAR(p[j], want.data[i * m + j], 1e-5) << "query " << i << " material " << j;
      sum += p[j];
    }
    EXPECT_NEAR(sum, 1.0, 1e-5);
    // The ranking: -ln p, best first, every candidate, valid = observed elements.
    const auto c = clf.classify(query.data(), n);
    ASSERT_EQ(c.ranking.size(), m);
    std::size_t argmax = 0;
    for (std::size_t j = 1; j < m; ++j)
      if (want.data[i * m + j] > want.data[i * m + argmax]) argmax = j;
    EXPECT_EQ(c.best().index, argmax);
    EXPECT_NEAR(c.best().distance, -std::log(want.data[i * m + argmax]), 1e-4);
    EXPECT_TRUE(std::isnan(c.best().fit));
    std::uint32_t valid = 0;
    for (const float v : query) valid += std::isnan(v) ? 0U : 1U;
    EXPECT_EQ(c.best().valid, valid);
    for (std::size_t j = 1; j < m; ++j) EXPECT_LE(c.ranking[j - 1].distance, c.ranking[j].distance);
  }
}

TEST(OnnxClassifier, RenormalisesOverTheCandidates) {
  const std::vector<std::uint32_t> cands = {3, 11, 20};
  const OnnxClassifier all(real_table(), (kData / "tiny_mlp.onnx").string(), {}, kLibrary);
  const OnnxClassifier some(real_table(), (kData / "tiny_mlp.onnx").string(), cands, kLibrary);
  const auto q = tofmat::read_npy_file(kData / "queries.npy");
  std::vector<float> query(q.shape[1]);
  for (std::size_t k = 0; k < query.size(); ++k) query[k] = static_cast<float>(q.data[4 * q.shape[1] + k]);
  const auto p = all.probabilities(query.data(), query.size());
  const auto c = some.classify(query.data(), query.size());
  ASSERT_EQ(c.ranking.size(), 3U);
  const double total = p[3] + p[11] + p[20];
  double sum = 0.0;
  for (const auto& r : c.ranking) {
    EXPECT_NEAR(std::exp(-r.distance), p[r.index] / total, 1e-6);
    sum += std::exp(-r.distance);
  }
  EXPECT_NEAR(sum, 1.0, 1e-9);
}

TEST(OnnxClassifier, AProbabilityOfZeroIsAFiniteDistance) {
  // saturated.onnx gives material 0 everything: the others get e^-200 in float32, which is 0
  // (onnxruntime on x86-64) or a subnormal (on aarch64, about e^-90.7).
  const OnnxClassifier clf(real_table(), (kData / "saturated.onnx").string(), {}, kLibrary);
  const auto q = tofmat::read_npy_file(kData / "queries.npy");
  std::vector<float> query(q.shape[1]);
  for (std::size_t k = 0; k < query.size(); ++k) query[k] = static_cast<float>(q.data[k]);
  const auto p = clf.probabilities(query.data(), query.size());
  EXPECT_EQ(p[0], 1.0F);
  EXPECT_LT(p[1], 1.2e-38F);  // 0 or subnormal
  const auto c = clf.classify(query.data(), query.size());
  EXPECT_EQ(c.best().index, 0U);
  EXPECT_NEAR(c.best().distance, 0.0, 1e-9);
  for (std::size_t j = 1; j < c.ranking.size(); ++j) {
    // Finite whatever the platform gave: from -ln(2^-126) (the smallest normal) to -ln(2^-149).
    EXPECT_GE(c.ranking[j].distance, 87.3);
    EXPECT_LE(c.ranking[j].distance, 103.28);
    EXPECT_EQ(c.ranking[j].distance, c.ranking[1].distance);  // the same logit for all of them
    EXPECT_EQ(c.ranking[j].index, j);                         // ties: the lower index first
  }
}

TEST(OnnxClassifier, RefusesBadQueries) {
  const OnnxClassifier clf(real_table(), (kData / "tiny_mlp.onnx").string(), {}, kLibrary);
  const std::size_t n = real_table()->elements_per_material();
  std::vector<float> q(n, std::numeric_limits<float>::quiet_NaN());
  EXPECT_THROW(clf.classify(q.data(), n), std::invalid_argument);  // nothing observed
  q[5] = std::numeric_limits<float>::infinity();
  EXPECT_THROW(clf.classify(q.data(), n), std::invalid_argument);
  q[5] = -3e38F;  // finite, but it would make the model's probabilities NaN
  EXPECT_THROW(clf.classify(q.data(), n), std::invalid_argument);
  q[5] = 1e6F;  // the bound itself: every probability finite
  for (const float p : clf.probabilities(q.data(), n)) EXPECT_TRUE(std::isfinite(p));
  q[5] = 3.0F;
  EXPECT_NO_THROW(clf.classify(q.data(), n));
  EXPECT_THROW(clf.classify(q.data(), n - 1), std::invalid_argument);
}

TEST(OnnxClassifier, RefusesModelsThatDoNotFit) {
  const auto path = (kData / "tiny_mlp.onnx").string();
  // Another table: the model's materials are the real database's 29.
  const auto& t = *real_table();
  const std::vector<float> values(t.values().begin(),
                                  t.values().begin() + static_cast<std::ptrdiff_t>(2 * t.elements_per_material()));
  const auto two = std::make_shared<const ExemplarTable>(std::vector<std::string>{t.materials()[0], t.materials()[1]},
                                                         t.rows(), t.bins(), values);
  EXPECT_THROW(OnnxClassifier(two, path, {}, kLibrary), std::invalid_argument);
  // The same materials and bins with one value moved: other curves.
  std::vector<float> moved = t.values();
  moved[0] = std::isnan(moved[0]) ? 1.0F : moved[0] + 0.5F;
  const auto other = std::make_shared<const ExemplarTable>(t.materials(), t.rows(), t.bins(), moved);
  EXPECT_THROW(OnnxClassifier(other, path, {}, kLibrary), std::invalid_argument);
  EXPECT_THROW(OnnxClassifier(real_table(), path, {99}, kLibrary), std::invalid_argument);
  // Not a model; no file; a file over the size bound is refused before it is read.
  const auto tmp = std::filesystem::temp_directory_path() / "tofmat_not_a_model.onnx";
  std::ofstream(tmp) << "not a model";
  EXPECT_THROW(OnnxClassifier(real_table(), tmp.string(), {}, kLibrary), std::runtime_error);
  EXPECT_THROW(OnnxClassifier(real_table(), "/nonexistent/model.onnx", {}, kLibrary), std::exception);
  std::filesystem::resize_file(tmp, tofmat::learn::kMaxModelBytes + 1);
  EXPECT_THROW(OnnxClassifier(real_table(), tmp.string(), {}, kLibrary), std::exception);
  std::filesystem::remove(tmp);
}

TEST(OnnxClassifier, RefusesAtLoadAModelWhoseOutputIsNoProbability) {
  // (issue 33) Each used to load and then fail every frame: the probe on each material's own curve
  // refuses them at load, naming the model, the material and what came out.
  for (const auto& [file, says] : std::vector<std::pair<std::string, std::string>>{
           {"logits.onnx", "not a probability"}, {"nan.onnx", "not a probability"}, {"short.onnx", "28 outputs"}}) {
    SCOPED_TRACE(file);
    try {
      const OnnxClassifier accepted(real_table(), (kData / file).string(), {}, kLibrary);
      ADD_FAILURE() << file << " was accepted";
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find(file), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find("own curve"), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find(says), std::string::npos) << e.what();
    }
  }
}

TEST(OnnxClassifier, SaysWhenTheLibraryCannotBeLoaded) {
  // A library that does not exist, or (when a test before this one in the
  // same process loaded the real one) a second library: refused, named.
  try {
    const OnnxClassifier clf(real_table(), (kData / "tiny_mlp.onnx").string(), {}, "/nonexistent/libonnxruntime.so.1");
    FAIL() << "a second library was accepted";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("/nonexistent/libonnxruntime.so.1"), std::string::npos) << e.what();
  }
}

#else

TEST(OnnxClassifier, IsUnavailableWithoutOnnxruntime) {
  EXPECT_FALSE(tofmat::learn::onnxruntime_built());
  try {
    const OnnxClassifier clf(real_table(), (kData / "tiny_mlp.onnx").string());
    FAIL() << "a build without onnxruntime ran a model";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("no onnxruntime support"), std::string::npos) << e.what();
  }
}

#endif

}  // namespace
