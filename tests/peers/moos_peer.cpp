// A MOOS app on libMOOS (core-moos, built by scripts/peers), for seabus's MOOS tests. It reads
// strings as MOOS apps do (MOOSValFromString) and talks to a real MOOSDB with libMOOS's own
// client (MOOS::MOOSAsyncCommClient, as CMOOSApp uses it). Text is passed in hex, so that commas,
// quotes, blanks and newlines cross the command line and standard streams as they are.
//
//   moos_peer lookup
//       reads lines "HEXTEXT HEXKEY..." on standard input; for each key prints "1:HEXVALUE" when
//       MOOSValFromString(value, text, key) finds it, else "0"; one line per line read
//   moos_peer notify HOST PORT NAME VAR S HEXTEXT | VAR D NUMBER ...
//       connects as NAME, writes each (string or double) in order, and exits once they are sent
//   moos_peer watch HOST PORT NAME SECS VAR...
//       connects as NAME, registers each VAR, prints "ready", then for SECS seconds prints each
//       notification: "VAR<TAB>S<TAB>HEXTEXT", "VAR<TAB>D<TAB>%.17g" or "VAR<TAB>B<TAB>HEX"
#include <MOOS/libMOOS/Comms/MOOSAsyncCommClient.h>
#include <MOOS/libMOOS/Utils/MOOSUtilityFunctions.h>

#include <cstdio>
#include <cstdlib>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

static std::string unhex(const std::string &h)
{
    std::string s;
    for (size_t i = 0; i + 1 < h.size(); i += 2)
        s.push_back(static_cast<char>(std::strtol(h.substr(i, 2).c_str(), nullptr, 16)));
    return s;
}

static std::string hex(const std::string &s)
{
    static const char *d = "0123456789abcdef";
    std::string h;
    for (unsigned char c : s) {
        h.push_back(d[c >> 4]);
        h.push_back(d[c & 15]);
    }
    return h;
}

static int lookup()
{
    std::string line;
    while (std::getline(std::cin, line)) {
        std::istringstream words(line);
        std::string text, key;
        words >> text;
        text = unhex(text);
        std::string out;
        while (words >> key) {
            std::string value;
            if (!out.empty())
                out += " ";
            out += MOOSValFromString(value, text, unhex(key)) ? "1:" + hex(value) : "0";
        }
        std::cout << out << std::endl;
    }
    return 0;
}

static bool connect(MOOS::MOOSAsyncCommClient &comms, const char *host, const char *port,
                    const char *name)
{
    comms.SetQuiet(true);
    comms.Run(host, std::atoi(port), name);
    if (!comms.WaitUntilConnected(10000)) {
        std::fprintf(stderr, "moos_peer: no MOOSDB at %s:%s within 10 s\n", host, port);
        return false;
    }
    return true;
}

static int notify(int argc, char **argv)
{
    MOOS::MOOSAsyncCommClient comms;
    if (!connect(comms, argv[2], argv[3], argv[4]))
        return 1;
    for (int i = 5; i + 2 < argc; i += 3) {
        std::string var = argv[i], kind = argv[i + 1], value = argv[i + 2];
        bool ok = kind == "D" ? comms.Notify(var, std::atof(value.c_str()))
                              : comms.Notify(var, unhex(value));
        if (!ok) {
            std::fprintf(stderr, "moos_peer: cannot notify %s\n", var.c_str());
            return 1;
        }
    }
    comms.Flush();
    // the client's writer sends on its own thread: let it, then leave politely
    MOOSPause(500);
    comms.Close(true);
    return 0;
}

static int watch(int argc, char **argv)
{
    MOOS::MOOSAsyncCommClient comms;
    if (!connect(comms, argv[2], argv[3], argv[4]))
        return 1;
    double until = MOOSLocalTime() + std::atof(argv[5]);
    for (int i = 6; i < argc; i++)
        comms.Register(argv[i], 0.0);
    // registrations are sent by the client's writer: give the DB a moment to take them
    MOOSPause(300);
    std::cout << "ready" << std::endl;
    while (MOOSLocalTime() < until) {
        MOOSMSG_LIST mail;
        if (comms.Fetch(mail)) {
            for (auto &m : mail) {
                if (m.IsBinary()) {
                    std::vector<unsigned char> v;
                    m.GetBinaryData(v);
                    std::cout << m.GetKey() << "\tB\t" << hex(std::string(v.begin(), v.end()));
                } else if (m.IsString()) {
                    std::cout << m.GetKey() << "\tS\t" << hex(m.GetString());
                } else {
                    char number[64];
                    std::snprintf(number, sizeof number, "%.17g", m.GetDouble());
                    std::cout << m.GetKey() << "\tD\t" << number;
                }
                std::cout << std::endl;
            }
        }
        MOOSPause(10);
    }
    comms.Close(true);
    return 0;
}

int main(int argc, char **argv)
{
    std::string mode = argc > 1 ? argv[1] : "";
    if (mode == "lookup")
        return lookup();
    if (mode == "notify" && argc >= 8 && (argc - 5) % 3 == 0)
        return notify(argc, argv);
    if (mode == "watch" && argc >= 7)
        return watch(argc, argv);
    std::fprintf(stderr,
                 "usage: moos_peer lookup | notify HOST PORT NAME (VAR S|D VALUE)... | "
                 "watch HOST PORT NAME SECS VAR...\n");
    return 2;
}
