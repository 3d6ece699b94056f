#include "loopsfm/report/top_view.h"

#include <algorithm>
#include <limits>

#include <Eigen/Eigenvalues>
#include <fmt/format.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "loopsfm/util/errors.h"

namespace loopsfm {
namespace {

cv::Scalar Bgr(const std::array<unsigned char, 3>& rgb) { return cv::Scalar(rgb[2], rgb[1], rgb[0]); }

}  // namespace

TopViewPlane FitTopViewPlane(const std::vector<Eigen::Vector3d>& centres) {
  LOOPSFM_CHECK(!centres.empty());
  TopViewPlane plane;
  for (const auto& c : centres) plane.mean += c;
  plane.mean /= static_cast<double>(centres.size());
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();
  for (const auto& c : centres) covariance += (c - plane.mean) * (c - plane.mean).transpose();
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eigen(covariance);
  plane.axis_u = eigen.eigenvectors().col(2);
  plane.axis_v = eigen.eigenvectors().col(1);
  return plane;
}

void WriteTopView(const std::filesystem::path& file, const std::vector<TopViewPath>& paths,
                  const std::vector<TopViewSegments>& segments, const std::string& title,
                  int size_px) {
  const TopViewPath* reference = nullptr;
  for (const TopViewPath& path : paths) {
    if (path.centres.size() >= 2) {
      reference = &path;
      break;
    }
  }
  if (!reference) throw InvalidArgument("top view: no path with two or more camera centres to plot");

  const TopViewPlane plane = FitTopViewPlane(reference->centres);
  auto project = [&](const Eigen::Vector3d& x) { return plane.Project(x); };

  Eigen::Vector2d lo = Eigen::Vector2d::Constant(std::numeric_limits<double>::max());
  Eigen::Vector2d hi = -lo;
  for (const TopViewPath& path : paths) {
    for (const auto& c : path.centres) {
      lo = lo.cwiseMin(project(c));
      hi = hi.cwiseMax(project(c));
    }
  }
  const int margin = size_px / 15;
  const int legend_height = 26 * static_cast<int>(paths.size() + segments.size()) + 40;
  const double extent = std::max({hi.x() - lo.x(), hi.y() - lo.y(), 1e-12});
  const double scale = (size_px - 2 * margin) / extent;
  const int height = static_cast<int>(scale * (hi.y() - lo.y())) + 2 * margin + legend_height;
  cv::Mat image(height, size_px, CV_8UC3, cv::Scalar(255, 255, 255));
  auto pixel = [&](const Eigen::Vector3d& x) {
    const Eigen::Vector2d p = project(x);
    return cv::Point(static_cast<int>(margin + scale * (p.x() - lo.x())),
                     static_cast<int>(legend_height + margin + scale * (hi.y() - p.y())));
  };

  for (const TopViewSegments& s : segments) {
    for (const auto& [a, b] : s.segments) cv::line(image, pixel(a), pixel(b), Bgr(s.rgb), 1, cv::LINE_AA);
  }
  for (const TopViewPath& path : paths) {
    for (size_t i = 1; i < path.centres.size(); ++i) {
      cv::line(image, pixel(path.centres[i - 1]), pixel(path.centres[i]), Bgr(path.rgb), 2,
               cv::LINE_AA);
    }
    if (!path.centres.empty()) cv::circle(image, pixel(path.centres.front()), 5, Bgr(path.rgb), -1);
  }

  const double font = 0.55;
  cv::putText(image, title, cv::Point(10, 24), cv::FONT_HERSHEY_SIMPLEX, font, cv::Scalar(0, 0, 0), 1,
              cv::LINE_AA);
  int y = 50;
  auto legend = [&](const std::string& label, const std::array<unsigned char, 3>& rgb, int thickness) {
    cv::line(image, cv::Point(12, y - 5), cv::Point(42, y - 5), Bgr(rgb), thickness, cv::LINE_AA);
    cv::putText(image, label, cv::Point(50, y), cv::FONT_HERSHEY_SIMPLEX, font, cv::Scalar(0, 0, 0), 1,
                cv::LINE_AA);
    y += 26;
  };
  for (const TopViewPath& path : paths) legend(path.label, path.rgb, 2);
  for (const TopViewSegments& s : segments) legend(s.label, s.rgb, 1);
  // Scale bar: a round length near a fifth of the plot.
  const double target = extent / 5.0;
  const double power = std::pow(10.0, std::floor(std::log10(target)));
  const double bar = target / power >= 5 ? 5 * power : target / power >= 2 ? 2 * power : power;
  const int bar_px = static_cast<int>(bar * scale);
  const cv::Point bar_start(size_px - margin - bar_px, y - 5);
  cv::line(image, bar_start, bar_start + cv::Point(bar_px, 0), cv::Scalar(0, 0, 0), 2);
  cv::putText(image, fmt::format("{:g}", bar), bar_start + cv::Point(0, -8), cv::FONT_HERSHEY_SIMPLEX,
              font, cv::Scalar(0, 0, 0), 1, cv::LINE_AA);

  if (!cv::imwrite(file.string(), image)) {
    throw InvalidArgument(fmt::format("top view: could not write '{}' (check the folder exists and "
                                      "the name ends in .png)", file.string()));
  }
}

}  // namespace loopsfm
