// Times CAPE (Proenca & Gao, IROS 2018) on a polymap sequence, the same frames `polymap
// bench` times: depth PNGs read and turned into CAPE's cell-ordered cloud (mm) once, then
// CAPE's own per-frame work (cell ordering + CAPE::process, what its run_cape_offline
// times) timed over `frames` frames, looping the sequence. Planes only (no cylinders: polymap
// fits planes), one thread (OpenCV's pool off). Prints one JSON line.
//
// CAPE is not part of polymap: scripts/bench_cape.sh compiles this file against a CAPE
// checkout given by path. Usage: cape_bench SEQ_DIR FRAMES [PATCH_SIZE]
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include <Eigen/Dense>
#include <opencv2/opencv.hpp>

#include "CAPE.h"

namespace fs = std::filesystem;

// `key = number` lines of the sequence's camera.toml.
static std::map<std::string, double> read_camera(const fs::path& path) {
    std::map<std::string, double> out;
    std::ifstream in(path);
    std::string line;
    while (std::getline(in, line)) {
        auto eq = line.find('=');
        if (eq == std::string::npos) continue;
        std::string key = line.substr(0, eq);
        key.erase(std::remove_if(key.begin(), key.end(), ::isspace), key.end());
        try {
            out[key] = std::stod(line.substr(eq + 1));
        } catch (...) {
        }
    }
    return out;
}

static double percentile(std::vector<double> v, double q) {
    std::sort(v.begin(), v.end());
    size_t rank = std::min(v.size(), std::max<size_t>(1, (size_t)std::ceil(q * v.size())));
    return v[rank - 1];
}

int main(int argc, char** argv) {
    if (argc < 3) {
        std::fprintf(stderr, "usage: cape_bench SEQ_DIR FRAMES [PATCH_SIZE]\n");
        return 2;
    }
    fs::path seq = argv[1];
    int frames = std::atoi(argv[2]);
    int patch = argc > 3 ? std::atoi(argv[3]) : 20;
    cv::setNumThreads(1);
    auto cam = read_camera(seq / "camera.toml");
    for (const char* k : {"width", "height", "fx", "fy", "cx", "cy", "depth_scale"}) {
        if (!cam.count(k)) {
            std::fprintf(stderr, "%s: no %s\n", (seq / "camera.toml").c_str(), k);
            return 2;
        }
    }
    int width = (int)cam["width"], height = (int)cam["height"];
    float fx = cam["fx"], fy = cam["fy"], cx = cam["cx"], cy = cam["cy"];
    float mm_per_unit = cam["depth_scale"] * 1000.0;
    if (width % patch || height % patch) {
        std::fprintf(stderr, "%dx%d is not a whole number of %d px cells\n", width, height, patch);
        return 2;
    }

    std::vector<fs::path> files;
    for (auto& e : fs::directory_iterator(seq / "depth"))
        if (e.path().extension() == ".png") files.push_back(e.path());
    std::sort(files.begin(), files.end());
    if (files.empty()) {
        std::fprintf(stderr, "%s: no depth PNGs\n", (seq / "depth").c_str());
        return 2;
    }

    // Image-ordered clouds (mm), one per frame, made before timing as polymap bench decodes first.
    std::vector<Eigen::MatrixXf> clouds;
    for (auto& f : files) {
        cv::Mat d = cv::imread(f.string(), cv::IMREAD_ANYDEPTH);
        if (d.empty() || d.cols != width || d.rows != height || d.type() != CV_16U) {
            std::fprintf(stderr, "%s: not a %dx%d 16-bit depth PNG\n", f.c_str(), width, height);
            return 2;
        }
        Eigen::MatrixXf cloud = Eigen::MatrixXf::Zero(width * height, 3);
        for (int r = 0; r < height; r++)
            for (int c = 0; c < width; c++) {
                float z = d.at<uint16_t>(r, c) * mm_per_unit;
                if (z <= 0) continue;
                int i = r * width + c;
                cloud(i, 0) = (c - cx) / fx * z;
                cloud(i, 1) = (r - cy) / fy * z;
                cloud(i, 2) = z;
            }
        clouds.push_back(std::move(cloud));
    }

    // Where each pixel goes in CAPE's cell-contiguous layout.
    int cells_w = width / patch;
    std::vector<int> cell_index(width * height);
    for (int r = 0; r < height; r++)
        for (int c = 0; c < width; c++)
            cell_index[r * width + c] =
                ((r / patch) * cells_w + c / patch) * patch * patch + (r % patch) * patch + c % patch;

    // run_cape_offline's settings: 15 deg and 50 mm to merge, planes only here.
    CAPE cape(height, width, patch, patch, false, std::cos(M_PI / 12), 50.0f);
    Eigen::MatrixXf organized(width * height, 3);
    cv::Mat_<uchar> seg(height, width, uchar(0));
    std::vector<double> ms;
    double planes = 0;
    int n = width * height;
    for (int k = -1; k < frames; k++) {  // frame -1 warms up
        const Eigen::MatrixXf& cloud = clouds[(k < 0 ? 0 : k) % clouds.size()];
        auto t0 = std::chrono::steady_clock::now();
        for (int i = 0; i < n; i++) {
            int j = cell_index[i];
            organized.data()[j] = cloud.data()[i];
            organized.data()[n + j] = cloud.data()[n + i];
            organized.data()[2 * n + j] = cloud.data()[2 * n + i];
        }
        int nr_planes = 0, nr_cylinders = 0;
        std::vector<PlaneSeg> plane_params;
        std::vector<CylinderSeg> cylinder_params;
        cape.process(organized, nr_planes, nr_cylinders, seg, plane_params, cylinder_params);
        auto t1 = std::chrono::steady_clock::now();
        if (k >= 0) {
            ms.push_back(std::chrono::duration<double, std::milli>(t1 - t0).count());
            planes += nr_planes;
        }
    }
    std::printf(
        "{\"sequence\": \"%s\", \"width\": %d, \"height\": %d, \"frames\": %d, \"patch\": %d, "
        "\"threads\": 1, \"median_ms\": %.4f, \"p99_ms\": %.4f, \"planes_per_frame\": %.2f}\n",
        seq.c_str(), width, height, frames, patch, percentile(ms, 0.5), percentile(ms, 0.99), planes / frames);
    return 0;
}
