// cloudcast-client's program logic, kept in the cloudcast_viewer_app library so that tests can
// reach the session and statistics without the binary. viewer/cloudcast_client.cc is only main()
// around ClientMain.
#pragma once

namespace cloudcast::client::app {

// Parses the command line, picks the frame source, streams through the server and shows,
// records and counts the clouds (or views local files with --open). Returns the exit status:
// 0 success, 1 failure while running (server, files, stream), 2 usage error (bad flags).
int ClientMain(int argc, char** argv);

}  // namespace cloudcast::client::app
