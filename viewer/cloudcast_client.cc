// cloudcast-client: streams stereo frames to a cloudcast server and shows, records or measures
// the clouds it sends back; also views local cloud files. See --help, and viewer/app/.
#include <cstdio>
#include <exception>

#include "app/app.h"

int main(int argc, char** argv) {
  try {
    return cloudcast::client::app::ClientMain(argc, argv);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "cloudcast-client: error: %s\n", e.what());
  } catch (...) {
    std::fprintf(stderr, "cloudcast-client: error: unknown exception\n");
  }
  return 1;
}
