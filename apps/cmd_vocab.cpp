// `tessera vocab train|info`: trains a bag-of-words vocabulary (visual_slam/vocabulary.hpp) on the
// ORB features of a folder of images or of an RGB-D sequence, and describes a vocabulary file.
// Exit codes: 0 ok; 2 usage errors (bad option values, a missing input); 1 unusable input contents.
#include "commands.hpp"

#include <tessera/datasets/rgbd_sequence.hpp>
#include <tessera/io/image_file.hpp>
#include <tessera/runtime/options.hpp>
#include <tessera/visual_slam/feature_extractor.hpp>
#include <tessera/visual_slam/vocabulary.hpp>

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <iomanip>
#include <iostream>
#include <memory>

namespace tessera::app {

namespace fs = std::filesystem;
namespace vs = tessera::visual_slam;

namespace {

struct TrainSettings {
  std::string images, rgbd, out;
  int k = 10;
  int levels = 5;
  int every = 1;
  int max_images = 0;
  int features = 1000;
  int iterations = 10;
  std::uint64_t seed = 5489;
};

// ORB descriptors of one grey image through the tracker's bucketed extractor, so the vocabulary
// sees the features the tracker will look up.
cv::Mat describe(const cv::Mat& gray, int features) {
  vs::FeatureExtractorOptions o;
  o.max_features = features;
  const double f = std::max(gray.cols, gray.rows);  // focal length: unused without depth
  const vs::FeatureExtractor ex(o, {f, f, gray.cols / 2.0, gray.rows / 2.0, gray.cols, gray.rows});
  return ex.extract(gray, cv::Mat(), 1000.0).descriptors;
}

cv::Mat readGray(const fs::path& path) {
  const auto ext = path.extension().string();
  if (ext == ".jpg" || ext == ".jpeg" || ext == ".JPG" || ext == ".JPEG") {
    auto rgb = io::decodeRgb8(io::readFileBytes(path), path.string());
    cv::Mat gray;
    cv::cvtColor(cv::Mat(rgb.height, rgb.width, CV_8UC3, rgb.pixels.data()), gray,
                 cv::COLOR_RGB2GRAY);
    return gray;
  }
  auto g = io::readGray8(path);
  return cv::Mat(g.height, g.width, CV_8UC1, g.pixels.data()).clone();
}

// The images to train on, in name order: every `every`-th file, at most max_images.
std::vector<fs::path> imageFiles(const TrainSettings& s) {
  std::vector<fs::path> all;
  for (const auto& e : fs::directory_iterator(s.images)) {
    auto ext = e.path().extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(),
                   [](unsigned char c) { return std::tolower(c); });
    // 7-Scenes folders hold depth PNGs beside the colour images: skip them.
    if (e.path().filename().string().find(".depth.") != std::string::npos) continue;
    if (e.is_regular_file() && (ext == ".png" || ext == ".pgm" || ext == ".jpg" || ext == ".jpeg"))
      all.push_back(e.path());
  }
  std::sort(all.begin(), all.end());
  std::vector<fs::path> chosen;
  for (std::size_t i = 0; i < all.size(); i += static_cast<std::size_t>(s.every)) {
    if (s.max_images > 0 && chosen.size() >= static_cast<std::size_t>(s.max_images)) break;
    chosen.push_back(all[i]);
  }
  return chosen;
}

std::vector<cv::Mat> collectDescriptors(const TrainSettings& s) {
  std::vector<cv::Mat> out;
  auto progress = [&out](std::size_t total, const std::string& name, const cv::Mat& d) {
    if (out.size() % 20 == 0 || out.size() == total)
      std::cerr << "features: " << out.size() << "/" << total << " images (" << name << ": "
                << d.rows << " descriptors)\n";
  };
  if (!s.images.empty()) {
    const auto files = imageFiles(s);
    if (files.empty()) throw ConfigError("--images " + s.images + ": no .png/.pgm/.jpg images");
    for (const auto& f : files) {
      out.push_back(describe(readGray(f), s.features));
      progress(files.size(), f.filename().string(), out.back());
    }
  } else {
    const auto seq = datasets::readRgbdSequence(s.rgbd);
    std::vector<std::size_t> frames;
    for (std::size_t i = 0; i < seq.frames.size(); i += static_cast<std::size_t>(s.every)) {
      if (s.max_images > 0 && frames.size() >= static_cast<std::size_t>(s.max_images)) break;
      frames.push_back(i);
    }
    if (frames.empty()) throw ConfigError("--rgbd " + s.rgbd + ": no frames");
    for (auto i : frames) {
      auto images = datasets::loadRgbdImages(seq, i);
      cv::Mat gray;
      cv::cvtColor(cv::Mat(images.height, images.width, CV_8UC3, images.color.data()), gray,
                   cv::COLOR_RGB2GRAY);
      out.push_back(describe(gray, s.features));
      progress(frames.size(), seq.frames[i].color_path.filename().string(), out.back());
    }
  }
  return out;
}

void printInfo(const vs::Vocabulary& voc, const std::string& path) {
  std::size_t inner = 0, zero_idf = 0;
  std::vector<std::size_t> per_depth(static_cast<std::size_t>(voc.levels()) + 1, 0);
  for (vs::NodeId id = 1; id <= voc.nodeCount(); ++id) {
    const auto& n = voc.node(id);
    ++per_depth[static_cast<std::size_t>(n.depth)];
    if (n.word < 0) ++inner;
  }
  double min_w = 1e300, max_w = 0, sum_w = 0;
  for (vs::WordId w = 0; w < voc.wordCount(); ++w) {
    const double x = voc.wordWeight(w);
    min_w = std::min(min_w, x);
    max_w = std::max(max_w, x);
    sum_w += x;
    zero_idf += x == 0;
  }
  std::cout << path << ": k " << voc.branching() << ", L " << voc.levels() << ", "
            << voc.nodeCount() << " nodes (" << inner << " inner), " << voc.wordCount()
            << " words (" << std::setprecision(3)
            << 100.0 * static_cast<double>(voc.wordCount()) /
                   std::pow(voc.branching(), voc.levels())
            << " % of k^L)\n"
            << "nodes per depth:";
  for (std::size_t d = 1; d < per_depth.size(); ++d) std::cout << " " << per_depth[d];
  std::cout << "\nidf: min " << min_w << ", mean " << sum_w / static_cast<double>(voc.wordCount())
            << ", max " << max_w << "; " << zero_idf << " words with idf 0\n";
}

}  // namespace

void addVocabCommand(CLI::App& app, int& result) {
  auto* vocab = app.add_subcommand("vocab", "bag-of-words vocabularies (ORB, DBoW3-compatible)");
  vocab->require_subcommand(1);

  auto* train = vocab->add_subcommand("train", "train a vocabulary tree on ORB features");
  auto s = std::make_shared<TrainSettings>();
  auto* images = train->add_option("--images", s->images, "folder of .png/.pgm/.jpg images");
  auto* rgbd = train->add_option("--rgbd", s->rgbd, "TUM RGB-D or 7-Scenes folder (colour images)");
  images->excludes(rgbd);
  train->add_option("--k", s->k, "branching factor")->capture_default_str();
  train->add_option("--L", s->levels, "depth of the tree")->capture_default_str();
  train->add_option("--every", s->every, "use every n-th image")->capture_default_str();
  train->add_option("--max-images", s->max_images, "at most this many images (0 = all)")
      ->capture_default_str();
  train->add_option("--features", s->features, "ORB features per image")->capture_default_str();
  train->add_option("--iterations", s->iterations, "k-medians iterations per node (max)")
      ->capture_default_str();
  train->add_option("--seed", s->seed, "seed of the k-means++ seeding")->capture_default_str();
  train->add_option("--out", s->out, "vocabulary file to write (our binary format)")->required();
  train->callback([s, &result] {
    if (s->images.empty() == s->rgbd.empty()) throw ConfigError("give one of --images or --rgbd");
    const auto& dir = s->images.empty() ? s->rgbd : s->images;
    if (!fs::is_directory(dir))
      throw ConfigError((s->images.empty() ? "--rgbd " : "--images ") + dir + ": no such folder");
    if (s->every < 1) throw ConfigError("--every must be >= 1");
    if (s->max_images < 0) throw ConfigError("--max-images must be >= 0");
    if (s->features < 1) throw ConfigError("--features must be >= 1");
    vs::VocabularyTrainOptions o;
    o.k = s->k;
    o.levels = s->levels;
    o.max_iterations = s->iterations;
    o.seed = s->seed;
    try {
      o.validate();
    } catch (const std::invalid_argument& e) {
      throw ConfigError(std::string("--k/--L/--iterations: ") + e.what());
    }
    const auto t0 = std::chrono::steady_clock::now();
    const auto descriptors = collectDescriptors(*s);
    std::size_t total = 0;
    for (const auto& d : descriptors) total += static_cast<std::size_t>(d.rows);
    const auto t1 = std::chrono::steady_clock::now();
    std::cerr << "training k " << o.k << ", L " << o.levels << " on " << total << " descriptors of "
              << descriptors.size() << " images\n";
    o.progress = [total](std::size_t nodes, std::size_t clustered) {
      std::cerr << "training: " << nodes << " inner nodes, " << clustered
                << " descriptor assignments (" << total << " per level)\n";
    };
    const auto voc = vs::Vocabulary::train(descriptors, o);
    const auto t2 = std::chrono::steady_clock::now();
    voc.save(s->out);
    const auto secs = [](auto a, auto b) { return std::chrono::duration<double>(b - a).count(); };
    std::cout << "wrote " << s->out << " (features " << std::setprecision(3) << secs(t0, t1)
              << " s, training " << secs(t1, t2) << " s)\n";
    printInfo(voc, s->out);
    result = 0;
  });

  auto* info =
      vocab->add_subcommand("info", "describe a vocabulary file (ours or DBoW2/DBoW3 YAML)");
  auto file = std::make_shared<std::string>();
  info->add_option("file", *file, "vocabulary file")->required();
  info->callback([file, &result] {
    if (!fs::is_regular_file(*file)) throw ConfigError(*file + ": no such file");
    printInfo(vs::Vocabulary::load(*file), *file);
    result = 0;
  });
}

}  // namespace tessera::app
