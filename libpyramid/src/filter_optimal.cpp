// The per-terrain optimal D (Losasso & Hoppe 2004, section 7 footnote): the 8-fold symmetric 11x11
// filter with DC gain 1 minimising ||T - U(D(T))||_2 on sample windows, by least squares.
//
// U and D are linear, so U(D(T)) = sum_k a_k U(D_k(T)) over the 21 orbit basis filters D_k. With the
// DC constraint a_0 = 1 - sum_{k>0} n_k a_k (n_k = orbit size) the problem becomes the unconstrained
// least squares  min || (T - P_0) - sum_{k>0} a_k (P_k - n_k P_0) ||  with P_k = U(D_k(T)).
#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>

#include "filter_downsample.h"
#include "pyramid/pyramid.h"

namespace terrain {
namespace {

constexpr int kOrbits = 21;
constexpr int kUnknowns = kOrbits - 1;
// Samples this close to a window edge see the reflected extension of D and U, not the terrain.
constexpr int64_t kMargin = 8;

std::array<double, kOrbits> default_orbit_weights() {
  std::array<double, kOrbits> w{};
  w[0] = 0.25, w[1] = 0.125, w[2] = 0.0625;
  return w;
}

DownsampleFilter fallback(FilterFitReport* report, const std::string& why) {
  if (report) {
    report->fallback = true;
    report->reason = why;
  }
  return DownsampleFilter::default_filter();
}

}  // namespace

std::string FilterFitReport::summary() const {
  std::ostringstream s;
  s << (fallback ? "D: default tent filter (fallback: " + reason + ")" : "D: least-squares optimal 11x11")
    << "; windows " << windows << ", equations " << equations << ", rank " << rank << "/" << kUnknowns
    << ", condition " << condition << "; sample rms optimal " << rms_optimal << ", default " << rms_default
    << ", impulse " << rms_impulse;
  return s.str();
}

std::vector<Rect> filter_fit_windows(GridSize level, const FilterFitOptions& options) {
  std::vector<Rect> out;
  const int64_t side = std::min({options.window, level.width, level.height});
  if (side < 3 * kMargin || options.max_windows <= 0) return out;
  int64_t nx = std::clamp<int64_t>(level.width / side, 1, 4), ny = std::clamp<int64_t>(level.height / side, 1, 4);
  while (nx * ny > options.max_windows) (nx >= ny ? nx : ny) -= 1;
  for (int64_t ty = 0; ty < ny; ++ty)
    for (int64_t tx = 0; tx < nx; ++tx) {
      const int64_t x = nx == 1 ? (level.width - side) / 2 : tx * (level.width - side) / (nx - 1);
      const int64_t y = ny == 1 ? (level.height - side) / 2 : ty * (level.height - side) / (ny - 1);
      out.push_back({x, y, side, side});
    }
  return out;
}

DownsampleFilter fit_optimal_filter(const std::vector<Rect>& windows,
                                    const std::vector<std::vector<int32_t>>& window_data,
                                    const FilterFitOptions& options, FilterFitReport* report) {
  if (report) *report = FilterFitReport{};
  if (windows.size() != window_data.size()) throw std::invalid_argument("fit_optimal_filter: window count mismatch");
  const auto& orbits = symmetric_orbits();

  // Count equations first so the design matrix is allocated once.
  int64_t rows = 0;
  for (const Rect& r : windows)
    if (r.width > 2 * kMargin && r.height > 2 * kMargin) rows += (r.width - 2 * kMargin) * (r.height - 2 * kMargin);
  if (report) {
    report->windows = int(windows.size());
    report->equations = rows;
  }
  if (rows < 4 * kUnknowns) return fallback(report, "too few samples to fit (grid smaller than 24x24)");

  Eigen::MatrixXd A(rows, kUnknowns);
  Eigen::VectorXd y(rows);
  int64_t row = 0;
  std::vector<double> coarse, pred0, predk;
  for (size_t wi = 0; wi < windows.size(); ++wi) {
    const Rect& r = windows[wi];
    if (r.width <= 2 * kMargin || r.height <= 2 * kMargin) continue;
    const GridSize fine{r.width, r.height};
    const GridSize cs{coarse_extent(r.width), coarse_extent(r.height)};
    if (int64_t(window_data[wi].size()) != r.width * r.height)
      throw std::invalid_argument("fit_optimal_filter: window data size mismatch");
    coarse.resize(size_t(cs.width * cs.height));
    pred0.resize(size_t(r.width * r.height));
    predk.resize(pred0.size());
    for (int k = 0; k < kOrbits; ++k) {
      std::array<double, kOrbits> unit{};
      unit[size_t(k)] = 1.0;
      const DownsampleFilter basis = DownsampleFilter::from_orbit_weights(unit, DownsampleFilter::Kind::Custom);
      detail::downsample_real(basis, window_data[wi].data(), fine, coarse.data());
      upsample_real(coarse.data(), fine, k == 0 ? pred0.data() : predk.data());
      if (k == 0) continue;
      int64_t rr = row;
      for (int64_t yy = kMargin; yy < r.height - kMargin; ++yy)
        for (int64_t xx = kMargin; xx < r.width - kMargin; ++xx, ++rr) {
          const size_t idx = size_t(yy * r.width + xx);
          A(rr, k - 1) = predk[idx] - orbits[size_t(k)].count * pred0[idx];
        }
    }
    for (int64_t yy = kMargin; yy < r.height - kMargin; ++yy)
      for (int64_t xx = kMargin; xx < r.width - kMargin; ++xx, ++row) {
        const size_t idx = size_t(yy * r.width + xx);
        y(row) = double(window_data[wi][idx]) - pred0[idx];
      }
  }

  // A lone feature (a spike, a single ridge) can make the matrix full rank with only a few hundred
  // informative equations: the fit would then chase that feature. Require enough of them.
  {
    const double tol = 1e-9 * std::max(1.0, y.cwiseAbs().maxCoeff());
    int64_t active = 0;
    for (int64_t r = 0; r < rows; ++r)
      if (std::abs(y(r)) > tol || A.row(r).cwiseAbs().maxCoeff() > tol) ++active;
    if (report) report->active_equations = active;
    if (active < options.min_active_equations)
      return fallback(report, "too few informative samples (" + std::to_string(active) + " non-flat equations)");
  }
  // Column scaling makes the rank/condition test about the shape of the data, not its amplitude.
  Eigen::VectorXd norms = A.colwise().norm();
  const double max_norm = norms.maxCoeff();
  const double n = double(rows);
  auto rms_of = [&](const Eigen::VectorXd& a) { return std::sqrt((y - A * a).squaredNorm() / n); };
  Eigen::VectorXd tent(kUnknowns);
  {
    auto w = default_orbit_weights();
    for (int k = 1; k < kOrbits; ++k) tent(k - 1) = w[size_t(k)];
  }
  if (report) {
    report->rms_impulse = std::sqrt(y.squaredNorm() / n);
    report->rms_default = rms_of(tent);
  }
  if (!(max_norm > 0) || !std::isfinite(max_norm) || (report && report->active_equations == 0)) {
    if (report) report->condition = std::numeric_limits<double>::infinity();
    return fallback(report, "flat sample: every basis filter predicts the same surface");
  }
  Eigen::VectorXd scale(kUnknowns);
  for (int k = 0; k < kUnknowns; ++k) scale(k) = norms(k) > 1e-12 * max_norm ? 1.0 / norms(k) : 0.0;
  Eigen::MatrixXd As = A * scale.asDiagonal();
  Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(As);
  qr.setThreshold(1e-10);
  const int rank = int(qr.rank());
  Eigen::MatrixXd gram = As.transpose() * As;
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(gram, Eigen::EigenvaluesOnly);
  const double lmin = eig.eigenvalues().minCoeff(), lmax = eig.eigenvalues().maxCoeff();
  const double cond = lmin > 0 ? std::sqrt(lmax / lmin) : std::numeric_limits<double>::infinity();
  if (report) {
    report->rank = rank;
    report->condition = cond;
  }
  if (rank < kUnknowns) return fallback(report, "rank-deficient sample (rank " + std::to_string(rank) + ")");
  if (!(cond <= options.max_condition)) return fallback(report, "ill-conditioned sample");

  Eigen::VectorXd a = scale.asDiagonal() * qr.solve(y);
  if (!a.allFinite()) return fallback(report, "non-finite solution");
  std::array<double, kOrbits> w{};
  double rest = 0;
  for (int k = 1; k < kOrbits; ++k) {
    w[size_t(k)] = a(k - 1);
    rest += orbits[size_t(k)].count * a(k - 1);
  }
  w[0] = 1.0 - rest;
  for (double v : w)
    if (!(std::abs(v) <= options.max_abs_tap)) return fallback(report, "filter coefficient out of bounds");
  const double rms_opt = rms_of(a);
  if (report) report->rms_optimal = rms_opt;
  const double rms_tent = rms_of(tent);
  if (!(rms_opt < rms_tent * (1.0 - 1e-9)))
    return fallback(report, "fit not better than the default filter on the sample");
  if (report) report->reason = "least squares fit";
  return DownsampleFilter::from_orbit_weights(w, DownsampleFilter::Kind::Optimal);
}

DownsampleFilter fit_optimal_filter(const int32_t* grid, GridSize level, const FilterFitOptions& options,
                                    FilterFitReport* report) {
  std::vector<Rect> windows = filter_fit_windows(level, options);
  std::vector<std::vector<int32_t>> data;
  for (const Rect& r : windows) {
    std::vector<int32_t> d(size_t(r.width * r.height));
    for (int64_t yy = 0; yy < r.height; ++yy)
      std::copy(grid + (r.y0 + yy) * level.width + r.x0, grid + (r.y0 + yy) * level.width + r.x0 + r.width,
                d.begin() + yy * r.width);
    data.push_back(std::move(d));
  }
  return fit_optimal_filter(windows, data, options, report);
}

}  // namespace terrain
