#include <tessera/io/module_path.hpp>

#include <dlfcn.h>

#include <system_error>

namespace tessera::io {

namespace module_path_detail {

void addDirectory(std::vector<std::filesystem::path>& dirs, const std::filesystem::path& dir) {
  if (dir.empty()) return;
  std::error_code ec;
  std::filesystem::path canonical = std::filesystem::weakly_canonical(dir, ec);
  if (ec) canonical = dir;
  for (const auto& d : dirs)
    if (d == canonical) return;
  dirs.push_back(canonical);
}

}  // namespace module_path_detail

std::vector<std::filesystem::path> moduleCandidates(std::string_view file_name,
                                                    const void* anchor) {
  namespace fs = std::filesystem;
  std::vector<fs::path> dirs;
  std::error_code ec;
  const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  if (!ec) module_path_detail::addDirectory(dirs, exe.parent_path());
  // The object holding `anchor`: the executable itself while the caller is a static library
  // (dli_fname is then argv[0], which /proc/self/exe already covers), a .so otherwise.
  Dl_info info{};
  if (anchor != nullptr && dladdr(anchor, &info) != 0 && info.dli_fname != nullptr &&
      info.dli_fname[0] != '\0') {
    const fs::path self = fs::absolute(info.dli_fname, ec);
    if (!ec) module_path_detail::addDirectory(dirs, self.parent_path());
  }
  std::vector<fs::path> files;
  for (const auto& dir : dirs) {
    files.push_back(dir / file_name);
    files.push_back((dir.parent_path() / "lib" / file_name).lexically_normal());
  }
  return files;
}

}  // namespace tessera::io
