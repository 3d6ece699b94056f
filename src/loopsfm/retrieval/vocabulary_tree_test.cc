#include "loopsfm/retrieval/vocabulary_tree.h"

#include <filesystem>
#include <fstream>
#include <map>
#include <set>

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include "loopsfm/retrieval/retrieval_test_data.h"
#include "loopsfm/util/errors.h"

namespace loopsfm {
namespace {

namespace fs = std::filesystem;
using retrieval_test::MakeClusters;

VocabTreeOptions TreeOptions(int branching, int depth) {
  VocabTreeOptions options;
  options.branching = branching;
  options.depth = depth;
  options.max_training_descriptors = 1000000;
  return options;
}

fs::path TempPath(const std::string& name) {
  return fs::temp_directory_path() / ("loopsfm_retrieval_test_" + name);
}

std::string ReadBytes(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

void WriteBytes(const fs::path& path, const std::string& bytes) {
  std::ofstream(path, std::ios::binary | std::ios::trunc) << bytes;
}

// Expects Load to throw InputError whose message contains `fragment`.
void ExpectLoadFails(const fs::path& path, const std::string& fragment) {
  try {
    VocabularyTree::Load(path);
    ADD_FAILURE() << "loaded " << path;
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find(fragment), std::string::npos) << e.what();
  }
}

class VocabularyTreeTest : public ::testing::Test {
 protected:
  // 100 clusters of 30 points, a 10 x 10 x 10 tree: deeper than the clusters need, so nodes
  // holding a single cluster split it further, but no leaf should mix two clusters.
  static void SetUpTestSuite() {
    Random random(42);
    data_ = new retrieval_test::ClusteredDescriptors(MakeClusters(100, 30, 4.0, random));
    tree_ = new VocabularyTree(VocabularyTree::Train(data_->points, TreeOptions(10, 3), random));
  }
  static void TearDownTestSuite() {
    delete data_;
    delete tree_;
  }
  static retrieval_test::ClusteredDescriptors* data_;
  static VocabularyTree* tree_;
};
retrieval_test::ClusteredDescriptors* VocabularyTreeTest::data_ = nullptr;
VocabularyTree* VocabularyTreeTest::tree_ = nullptr;

TEST_F(VocabularyTreeTest, LeavesArePure) {
  const VocabularyTree& tree = *tree_;
  EXPECT_GE(tree.NumWords(), 100);
  EXPECT_LE(tree.NumWords(), 1000);
  const std::vector<uint32_t> words = tree.QuantizeAll(data_->points);
  std::map<uint32_t, std::set<int>> clusters_of_word;
  std::map<int, std::set<uint32_t>> words_of_cluster;
  for (size_t i = 0; i < words.size(); ++i) {
    ASSERT_LT(words[i], static_cast<uint32_t>(tree.NumWords()));
    clusters_of_word[words[i]].insert(data_->cluster_of_point[i]);
    words_of_cluster[data_->cluster_of_point[i]].insert(words[i]);
  }
  for (const auto& [word, clusters] : clusters_of_word) {
    EXPECT_EQ(clusters.size(), 1u) << "word " << word << " mixes clusters";
  }
  // Every leaf was reached by training points (empty clusters are dropped).
  EXPECT_EQ(clusters_of_word.size(), static_cast<size_t>(tree.NumWords()));
  EXPECT_EQ(words_of_cluster.size(), 100u);
}

TEST_F(VocabularyTreeTest, WordCentresQuantiseToTheirOwnWord) {
  const VocabularyTree& tree = *tree_;
  for (int word = 0; word < tree.NumWords(); ++word) {
    const Eigen::Matrix<uint8_t, kDescriptorDim, 1> centre =
        tree.WordCentre(word).array().round().cwiseMax(0).cwiseMin(255).cast<uint8_t>();
    EXPECT_EQ(tree.Quantize(centre.data()), static_cast<uint32_t>(word));
  }
}

TEST_F(VocabularyTreeTest, QuantizeAllMatchesQuantize) {
  Random random(1);
  FeatureDescriptors descriptors(300, kDescriptorDim);
  for (int i = 0; i < 300; ++i) {
    for (int d = 0; d < kDescriptorDim; ++d) descriptors(i, d) = random.UniformInt(0, 255);
  }
  const std::vector<uint32_t> words = tree_->QuantizeAll(descriptors);
  ASSERT_EQ(words.size(), 300u);
  for (int i = 0; i < 300; ++i) EXPECT_EQ(words[i], tree_->Quantize(descriptors.row(i).data()));
  // Several sets in one descent, empty ones included.
  const FeatureDescriptors empty(0, kDescriptorDim);
  const auto sets = tree_->QuantizeAll({&data_->points, &empty, &descriptors});
  ASSERT_EQ(sets.size(), 3u);
  EXPECT_EQ(sets[0], tree_->QuantizeAll(data_->points));
  EXPECT_TRUE(sets[1].empty());
  EXPECT_EQ(sets[2], words);
}

TEST_F(VocabularyTreeTest, SaveLoadRoundTripQuantisesIdentically) {
  const fs::path path = TempPath("roundtrip.vocab");
  tree_->Save(path);
  const VocabularyTree loaded = VocabularyTree::Load(path);
  EXPECT_TRUE(loaded == *tree_);
  EXPECT_EQ(loaded.NumWords(), tree_->NumWords());
  EXPECT_EQ(loaded.Branching(), 10);
  EXPECT_EQ(loaded.Depth(), 3);
  EXPECT_EQ(loaded.QuantizeAll(data_->points), tree_->QuantizeAll(data_->points));
  EXPECT_FALSE(fs::exists(path.string() + ".partial"));
}

TEST_F(VocabularyTreeTest, LoadRejectsBadFiles) {
  const fs::path path = TempPath("good.vocab");
  tree_->Save(path);
  const std::string good = ReadBytes(path);

  const fs::path bad = TempPath("bad.vocab");
  WriteBytes(bad, good.substr(0, good.size() / 2));
  ExpectLoadFails(bad, "truncated");
  WriteBytes(bad, good.substr(0, 20));
  ExpectLoadFails(bad, "truncated");
  WriteBytes(bad, good.substr(0, good.size() - 1));
  ExpectLoadFails(bad, "truncated");
  WriteBytes(bad, good + "x");
  ExpectLoadFails(bad, "unexpected bytes");
  WriteBytes(bad, "# COLMAP cameras.txt\n1 PINHOLE 640 480 500 500 320 240\n");
  ExpectLoadFails(bad, "not a loopsfm vocabulary tree");
  WriteBytes(bad, "");
  ExpectLoadFails(bad, "not a loopsfm vocabulary tree");
  std::string flipped = good;
  flipped[good.size() / 2] ^= 0x10;  // inside the centres
  WriteBytes(bad, flipped);
  ExpectLoadFails(bad, "checksum");
  std::string version = good;
  version[8] = 99;  // format version field
  WriteBytes(bad, version);
  ExpectLoadFails(bad, "format version 99");
  ExpectLoadFails(TempPath("does_not_exist.vocab"), "no such file");
  ExpectLoadFails(fs::temp_directory_path(), "no such file");
}

TEST(VocabularyTree, SameTreeForSameSeedAndAnyThreadCount) {
  Random data_random(9);
  // Overlapping clusters: k-means has real work to do at every node.
  const auto data = MakeClusters(50, 60, 30.0, data_random);
  const VocabTreeOptions options = TreeOptions(8, 3);
  Random a(123), b(123), c(124);
  const VocabularyTree tree_a = VocabularyTree::Train(data.points, options, a);
  VocabularyTree tree_b;
  {
    tbb::global_control one_thread(tbb::global_control::max_allowed_parallelism, 1);
    tree_b = VocabularyTree::Train(data.points, options, b);
  }
  EXPECT_TRUE(tree_a == tree_b);
  EXPECT_EQ(tree_a.QuantizeAll(data.points), tree_b.QuantizeAll(data.points));
  EXPECT_FALSE(tree_a == VocabularyTree::Train(data.points, options, c));
}

TEST(VocabularyTree, SmallInputsMakeEarlyLeaves) {
  Random random(2);
  const auto data = MakeClusters(5, 1, 0.0, random);
  const VocabularyTree tiny = VocabularyTree::Train(data.points, TreeOptions(10, 4), random);
  EXPECT_EQ(tiny.NumWords(), 1);
  EXPECT_EQ(tiny.Quantize(data.points.row(3).data()), 0u);

  // 3 distinct descriptors repeated: one split into 3 leaves, which cannot split further.
  FeatureDescriptors repeated(60, kDescriptorDim);
  for (int i = 0; i < 60; ++i) repeated.row(i) = data.points.row(i % 3);
  const VocabularyTree three = VocabularyTree::Train(repeated, TreeOptions(4, 5), random);
  EXPECT_EQ(three.NumWords(), 3);
  EXPECT_EQ(three.NumNodes(), 4);
}

TEST(VocabularyTree, TrainsOnASampleOfTheInputSets) {
  Random random(4);
  const auto a = MakeClusters(10, 40, 5.0, random);
  const auto b = MakeClusters(10, 40, 5.0, random);
  FeatureDescriptors empty(0, kDescriptorDim);
  const std::vector<const FeatureDescriptors*> sets = {&a.points, &empty, &b.points};

  Random sample_random(8);
  const FeatureDescriptors all = SampleDescriptors(sets, 1000, sample_random);
  ASSERT_EQ(all.rows(), 800);
  EXPECT_EQ(all.topRows(400), a.points);
  EXPECT_EQ(all.bottomRows(400), b.points);

  const FeatureDescriptors sample = SampleDescriptors(sets, 100, sample_random);
  ASSERT_EQ(sample.rows(), 100);
  auto row_bytes = [](const FeatureDescriptors& d, int i) {
    return std::string(reinterpret_cast<const char*>(d.row(i).data()), kDescriptorDim);
  };
  std::set<std::string> input_rows, sample_rows;
  for (int i = 0; i < 800; ++i) input_rows.insert(row_bytes(all, i));
  for (int i = 0; i < 100; ++i) sample_rows.insert(row_bytes(sample, i));
  EXPECT_EQ(sample_rows.size(), 100u);  // distinct rows picked
  for (const auto& row : sample_rows) EXPECT_TRUE(input_rows.count(row));

  VocabTreeOptions options = TreeOptions(4, 2);
  options.max_training_descriptors = 100;
  Random train_a(6), train_b(6);
  EXPECT_TRUE(VocabularyTree::Train(sets, options, train_a) ==
              VocabularyTree::Train(sets, options, train_b));
}

TEST(VocabularyTree, RejectsBadOptionsAndNoData) {
  VocabTreeOptions options;
  EXPECT_NO_THROW(options.Check());
  options.branching = 1;
  EXPECT_THROW(options.Check(), InvalidArgument);
  options = VocabTreeOptions();
  options.depth = 0;
  EXPECT_THROW(options.Check(), InvalidArgument);
  options = VocabTreeOptions();
  options.max_training_descriptors = 1;
  EXPECT_THROW(options.Check(), InvalidArgument);
  Random random;
  EXPECT_THROW(
      VocabularyTree::Train(FeatureDescriptors(0, kDescriptorDim), VocabTreeOptions(), random),
      InvalidArgument);
}

}  // namespace
}  // namespace loopsfm
